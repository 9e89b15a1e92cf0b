"""The ROS picture of a cell of several robots, as ``run`` deploys it (one bridge per robot on one transport).

RViz and Foxglove must see every robot where it stands in the cell's world frame and under the cell's names:
each bridge publishes its robot's URDF on ``/<robot>/robot_description``, rooted at ``world`` with the robot's
base on ``/tf_static`` and its links and joints under the cell's prefix, and its moving links on ``/tf`` from
the same joint states it puts on ``/joint_states``.  Checked for the side-by-side cell (a KUKA and a Viper both
calling their arm ``arm``, told apart by the prefixes ``kuka_`` and ``viper_``) and the KUKA + Nextage cell (no
prefixes; the Nextage at the world's origin), after a motion of every arm: the URDFs parse (pinocchio), their
joints are exactly those on /joint_states, and the tf chain from ``world`` to each TCP is the TCP the bridge
reports.  The DDS form (``launch``'s bridge processes) is test_cell_tf_placed_dds.py.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from cell_picture import TF_STATIC_LISTENER, Picture, check, description_topic
from fjt_client import RSI, make_backend

from app_functions.registry import full_catalog
from cell_runner.deployment import bridge_parts
from core_functions.cell_robots import CellRobotModel
from core_functions.geometry import Pose
from core_functions.primitives import MotionResult, MoveJoints
from core_functions.robots import KUKA_KR
from core_functions.urdf_tree import UrdfTree
from execution_engine.app_model import load_application
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import String, TFMessage
from node_transport.port import poll_until
from node_transport.qos import ROBOT_DESCRIPTION
from node_transport.transforms import compose_to_root
from robot_bridges.backend import BackendOptions
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.cell_backend import CellBackend, Part, member_options
from robot_bridges.placed import PlacedBackend
from robot_bridges.placed_urdf import placed_urdf
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "apps_xml" / "examples"
BOUND = 30.0  # simulated s


def cell_robot(app: str) -> CellRobotModel:
    robot = load_application(EXAMPLES / app, full_catalog()).robot
    assert isinstance(robot, CellRobotModel)
    return robot


async def cell_backend(robot: CellRobotModel, clock: Clock) -> CellBackend:
    """The cell's back end as its factory builds it (every robot placed), the KUKA's simulator in lockstep with the
    simulated clock (the factory's runs on the wall clock)."""
    parts = []
    for member in robot.members:
        if member.backend == "kuka-rsi":
            inner = await make_backend(RSI, clock)
        else:
            inner = await create_backend(member.backend, clock, member_options(BackendOptions(robot=robot), member))
        parts.append(Part(member, PlacedBackend(inner, member.base, member.name, member.names)))
    return CellBackend(tuple(parts))


@pytest.mark.parametrize("app", ["side_by_side.xml", "mixed_cell.xml"])
def test_every_robot_of_the_cell_is_drawn_at_its_base_under_the_cells_names(run_sim: Any, app: str) -> None:
    robot = cell_robot(app)

    async def main(clock: Clock) -> Picture:
        backend = await cell_backend(robot, clock)
        bus = LocalTransport(clock)
        picture = Picture()
        picture.listen(bus.create_node("rviz"), robot)
        bridges = [BridgeNode(bus.create_node(f"{name}_bridge"), part) for name, part in bridge_parts(backend)]
        try:
            for bridge in bridges:
                await bridge.start()
            for group in robot.group_names:  # every arm away from where it started: tf follows the motion
                limits = backend.joint_limits(group)
                if limits is None or backend.tcp_pose(group) is None:
                    continue
                names, positions = backend.joint_state()
                now = dict(zip(names, positions))
                target = tuple(now[j] + 0.1 for j in limits.joint_names)
                moved = await backend.execute(group, MoveJoints(target, joint_names=limits.joint_names))
                assert isinstance(moved, MotionResult), moved
            picture.states.clear()
            picture.tf.clear()
            for sent in picture.tcp.values():
                sent.clear()
            assert await poll_until(clock, lambda: picture.complete(robot), BOUND, 0.05)
            return picture
        finally:
            for bridge in bridges:
                await bridge.close()
            await backend.close()

    picture = run_sim(main)
    check(picture, robot)
    if app == "side_by_side.xml":  # the two robots' links told apart by the cell's prefixes, each hung from the world
        kuka, viper = (UrdfTree(picture.descriptions[description_topic(m)]) for m in robot.members)
        assert {"kuka_base_link", "kuka_tool0"} <= set(kuka.links) and "base_link" not in kuka.links
        assert {"viper_base_link", "viper_flange"} <= set(viper.links) and not set(kuka.links) & set(viper.links) - {"world"}
    mounts = {t.child_frame_id: t for m in picture.static for t in m.transforms if t.header.frame_id == "world"}
    for member in robot.members:  # world -> the robot's root on /tf_static: its base pose from the cell
        root = member.names.prefix + {"kuka-rsi": "base", "vplus": "world", "nextage-sim": "WAIST"}[member.backend]
        v, q = mounts[root].transform.translation, mounts[root].transform.rotation
        base = member.base
        assert Pose(v.x, v.y, v.z, q.x, q.y, q.z, q.w).distance_to(base) < 1e-9 and Pose(0, 0, 0, q.x, q.y, q.z, q.w).angle_to(base) < 1e-7


def test_a_robot_whose_root_is_the_world_and_has_no_prefix_stands_in_the_cells_world_itself() -> None:
    """A Viper (root link ``world``) without a prefix would meet the cell's world by name: its root is the world
    and the base pose goes into the joint on it -- one ``world`` link, the flange where the placement puts it."""
    urdf = (ROOT / "robot_bridges" / "vplus" / "urdf" / "adept_viper_s850.urdf").read_text()
    base = Pose.from_xyz_rpy(1.5, 0.2, 0.1, 0.0, 0.0, 3.0)
    own, placed = UrdfTree(urdf), UrdfTree(placed_urdf(urdf, base, "", "world_mount"))
    assert placed.links.count("world") == 1 and placed.movable_joints == own.movable_joints
    q = (0.3, -0.4, 0.5, 0.2, -0.6, 0.7)
    flange = {}
    for name, tree in (("own", own), ("placed", placed)):
        joints = [*tree.fixed_transforms(), *tree.movable_transforms(tree.movable_joints, q)]
        flange[name] = compose_to_root({j.child: (j.parent, pose) for j, pose in joints}, "flange")
    assert flange["own"][0] == flange["placed"][0] == "world"
    expected = base.compose(flange["own"][1])
    assert expected.distance_to(flange["placed"][1]) < 1e-9 and expected.angle_to(flange["placed"][1]) < 1e-9


def test_a_robot_its_own_driver_draws_gets_its_base_on_tf_static_and_no_urdf_of_the_bridges(run_sim: Any) -> None:
    """A ros2-control robot placed in a cell: its driver's robot_state_publisher publishes its URDF and links (under
    the driver's names); its bridge publishes no URDF of its own but world -> the driver's root link at the base."""
    base = Pose.from_xyz_rpy(0.35, -0.9, -0.1, 0.0, 0.0, 1.5707963)
    urdf = ROOT / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf"

    async def main(clock: Clock) -> tuple[list[TFMessage], list[String]]:
        inner = await create_backend("ros2-control", clock, BackendOptions(robot=KUKA_KR, extra={"transport": "model", "urdf": str(urdf)}))
        bus = LocalTransport(clock)
        static: list[TFMessage] = []
        described: list[String] = []
        viewer = bus.create_node("rviz")
        viewer.create_subscription(TFMessage, "/tf_static", static.append, TF_STATIC_LISTENER)
        viewer.create_subscription(String, "/feeder/robot_description", described.append, ROBOT_DESCRIPTION)
        bridge = BridgeNode(bus.create_node("feeder_bridge"), PlacedBackend(inner, base, "feeder"))
        await bridge.start()
        await clock.sleep(0.2)
        await bridge.close()
        await inner.close()
        return static, described

    static, described = run_sim(main)
    assert described == []
    mounts = [t for m in static for t in m.transforms]
    assert [(t.header.frame_id, t.child_frame_id) for t in mounts] == [("world", "base")]  # the KUKA URDF's root
    v, q = mounts[0].transform.translation, mounts[0].transform.rotation
    placed = Pose(v.x, v.y, v.z, q.x, q.y, q.z, q.w)
    assert placed.distance_to(base) < 1e-9 and placed.angle_to(base) < 1e-7
