"""Which URDF and which TCPs a robot's collision model uses.

The URDFs are the ones the bridges publish as ``robot_description`` (their ``<collision>``
elements are the collision model); the TCPs are where each bridge puts an arm's tool point, so
the held part sits where the skills hold it.
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import replace
from pathlib import Path

from lxml import etree

from core_functions.cell_robots import CellRobotModel
from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN, RobotModel
from robot_bridges.collision.scene import DEFAULT_MARGIN, ArmTcp, CollisionScene

_ROOT = Path(__file__).resolve().parents[1]
#: The Nextage's TCP: the wrist flange, z out of the hand (robot_bridges.nextage_sim.backend.HAND_TOOL).
NEXTAGE_HAND = Pose.from_xyz_rpy(0.0, 0.0, 0.0, 0.0, -math.pi / 2, 0.0)
MODELS: dict[str, tuple[Path, dict[str, ArmTcp]]] = {
    NEXTAGE_OPEN.name: (
        _ROOT / "nextage_sim" / "urdf" / "nextage_open.urdf",
        {"left_arm": ArmTcp("LARM_JOINT5_Link", NEXTAGE_HAND), "right_arm": ArmTcp("RARM_JOINT5_Link", NEXTAGE_HAND)},
    ),
    ADEPT_VIPER_S850.name: (_ROOT / "vplus" / "urdf" / "adept_viper_s850.urdf", {"arm": ArmTcp("flange")}),
    KUKA_KR.name: (_ROOT / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf", {"arm": ArmTcp("tool0")}),
}


def scene_for(robot: RobotModel, margin: float = DEFAULT_MARGIN) -> CollisionScene:
    """The collision model of ``robot`` (KeyError for a robot without one); a mixed cell's is every
    robot's, each base placed where the cell says, so a robot's links are checked against the others'."""
    if isinstance(robot, CellRobotModel):
        urdf_text, tcps = cell_urdf(robot)
        with tempfile.TemporaryDirectory(prefix="cell_urdf_") as folder:  # pinocchio reads a URDF from a file
            path = Path(folder) / f"{robot.name}.urdf"
            path.write_text(urdf_text, encoding="utf-8")
            return CollisionScene(robot, path, tcps, margin)
    urdf, tcps = MODELS[robot.name]
    return CollisionScene(robot, urdf, tcps, margin)


def cell_urdf(robot: CellRobotModel) -> tuple[str, dict[str, ArmTcp]]:
    """One URDF of every robot of the cell and their TCPs: each robot's links and fixed joints named
    ``ROBOT/NAME`` (two robots may both have a ``base_link``), its moving joints as the cell names them
    (the groups name them: their own names, or with the robot's ``prefix``), its root link fixed to the cell's ``world`` at the robot's base pose.  KeyError for a
    robot without a collision model."""
    root = etree.Element("robot", name=robot.name)
    etree.SubElement(root, "link", name="world")
    tcps: dict[str, ArmTcp] = {}
    for member in robot.members:
        urdf, member_tcps = MODELS[member.model.name]
        tree = etree.parse(str(urdf), etree.XMLParser(resolve_entities=False, no_network=True))
        prefix = f"{member.name}/"
        children = {j.find("child").get("link") for j in tree.getroot().iter("joint") if j.find("child") is not None}
        roots = [link.get("name") for link in tree.getroot().iter("link") if link.get("name") not in children]
        for element in tree.getroot():
            if not isinstance(element.tag, str) or element.tag not in ("link", "joint"):
                continue
            if element.tag == "link" or element.get("type") == "fixed":
                element.set("name", prefix + element.get("name", ""))
            else:  # a moving joint: the cell's name of it, as /joint_states and the groups carry it
                element.set("name", member.names.joint(element.get("name", "")))
            for end in ("parent", "child"):
                node = element.find(end) if element.tag == "joint" else None
                if node is not None:
                    node.set("link", prefix + node.get("link", ""))
            root.append(element)
        mount = etree.SubElement(root, "joint", name=f"{prefix}mount", type="fixed")
        etree.SubElement(mount, "parent", link="world")
        etree.SubElement(mount, "child", link=prefix + roots[0])
        base = member.base
        etree.SubElement(mount, "origin", xyz=" ".join(repr(v) for v in base.position), rpy=" ".join(repr(v) for v in base.rpy()))
        tcps.update({member.names.group(group): replace(tcp, frame=prefix + tcp.frame) for group, tcp in member_tcps.items()})
    return etree.tostring(root, encoding="unicode"), tcps
