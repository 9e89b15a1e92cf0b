"""A robot's URDF as its cell sees it: hung from the cell's world frame at its base, its names prefixed.

A robot of a cell of several publishes its own URDF (:mod:`robot_bridges.robot_state`), but RViz and
Foxglove must see it where it stands and under the names ``/joint_states`` gives its joints.  So
the URDF is rewritten the way a multi-robot description (a xacro with a ``prefix`` argument) is
written: every link and joint name carries the cell's prefix (``kuka_``: ``kuka_A1``,
``kuka_base_link``; two robots' ``base_link`` no longer meet in ``tf``), and a fixed joint holds the
robot's root link in the cell's ``world`` at its base pose.  robot_state_publisher's arithmetic
then gives ``world -> <root>`` on ``tf_static`` with the other fixed joints and the moving links
on ``tf``, one tree from the cell's world frame to every robot's tool.

A robot whose own root is already called ``world`` (the Viper's) and that has no prefix would
meet the cell's world frame by name: its root *is* then the cell's world, and the base pose goes
into the joints that hang from it instead of into a mount joint.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

from core_functions.geometry import Pose


def _origin(joint: ET.Element) -> Pose:
    origin = joint.find("origin")
    if origin is None:
        return Pose()
    xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in origin.get("rpy", "0 0 0").split()]
    return Pose.from_xyz_rpy(*xyz, *rpy)


def _set_origin(joint: ET.Element, pose: Pose) -> None:
    origin = joint.find("origin")
    if origin is None:
        origin = ET.Element("origin")
        joint.insert(0, origin)
    origin.set("xyz", " ".join(repr(v) for v in pose.position))
    origin.set("rpy", " ".join(repr(v) for v in pose.rpy()))


def root_link(robot: ET.Element) -> str:
    """The link no joint has as its child (a URDF has exactly one)."""
    children = {c.get("link") for j in robot.iter("joint") if (c := j.find("child")) is not None}
    roots = [name for link in robot.findall("link") if (name := link.get("name", "")) not in children]
    if len(roots) != 1:
        raise ValueError(f"URDF of {robot.get('name')!r}: {len(roots)} root links ({', '.join(roots) or 'none'}), a robot has one")
    return roots[0]


def placed_urdf(urdf: str, base: Pose, prefix: str, mount: str, world: str = "world") -> str:
    """``urdf`` with every link and joint name prefixed by ``prefix`` and its root held in ``world`` at
    ``base`` by the fixed joint ``mount`` (ValueError for a URDF without one root link)."""
    robot = ET.fromstring(urdf)
    root = root_link(robot)
    for link in robot.findall("link"):
        link.set("name", prefix + link.get("name", ""))
    for joint in robot.iter("joint"):
        joint.set("name", prefix + joint.get("name", ""))
        for tag in ("parent", "child"):
            element = joint.find(tag)
            if element is not None:
                element.set("link", prefix + element.get("link", ""))
        mimic = joint.find("mimic")
        if mimic is not None:
            mimic.set("joint", prefix + mimic.get("joint", ""))
    placed_root = prefix + root
    if placed_root == world:  # the robot's root is the cell's world: the base goes into the joints on it
        for joint in robot.iter("joint"):
            parent = joint.find("parent")
            if parent is not None and parent.get("link") == world:
                _set_origin(joint, base.compose(_origin(joint)))
    else:
        ET.SubElement(robot, "link", name=world)
        joint = ET.SubElement(robot, "joint", name=mount, type="fixed")
        ET.SubElement(joint, "parent", link=world)
        ET.SubElement(joint, "child", link=placed_root)
        _set_origin(joint, base)
    return ET.tostring(robot, encoding="unicode")
