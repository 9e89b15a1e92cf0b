"""The bridge as robot_state_publisher: the URDF on robot_description, the links on tf / tf_static.

With the real Nextage simulator behind a real bridge node on the local transport, in simulated
time: what RViz's RobotModel display and a tf2 listener would receive, and that composing the
published transforms gives the same TCP pose the bridge reports (so the forward kinematics on
tf are the simulator's).
"""
from __future__ import annotations

import math
import runpy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import setuptools
from robot_bridges.kuka_rsi.backend import KukaRsiBackend
from robot_bridges.vplus.backend import VPlusBackend
from scripted_backend import ScriptedBackend

from core_functions.geometry import Pose
from core_functions.primitives import MoveJoints
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN
from core_functions.urdf_tree import UrdfTree
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import JointState, String, TFMessage, Time
from node_transport.port import Node
from node_transport.qos import ROBOT_DESCRIPTION, SENSOR, TF, TF_STATIC
from node_transport.transforms import compose_to_root, tree_of
from node_transport.wire import JOINT_STATES, ROBOT_DESCRIPTION_TOPIC, TF_STATIC_TOPIC, TF_TOPIC
from robot_bridges.backend import BackendOptions
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.nextage_sim.backend import NextageSimBackend
from robot_bridges.registry import create_backend
from robot_bridges.robot_state import RobotStatePublisher

ROOT = Path(__file__).resolve().parents[1]
NEXTAGE_URDF = ROOT / "robot_bridges" / "nextage_sim" / "urdf" / "nextage_open.urdf"

# base -> l1 (revolute z) -> tool0 (fixed); l1 -> l2 (continuous y); l1 -> slide (prismatic x)
SMALL_URDF = """<robot name="small">
  <link name="base"/><link name="l1"/><link name="tool0"/><link name="l2"/><link name="slide"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l1"/><child link="tool0"/><origin xyz="0.1 0 0" rpy="0 1.5707963267948966 0"/></joint>
  <joint name="j2" type="continuous"><parent link="l1"/><child link="l2"/><origin xyz="0 0.2 0"/><axis xyz="0 1 0"/></joint>
  <joint name="p" type="prismatic"><parent link="l1"/><child link="slide"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


class Inbox:
    """Every message of one topic, with the epoch time it arrived at."""

    def __init__(self, node: Node, msg_type: type, topic: str, qos: Any) -> None:
        self.items: list[tuple[Any, float]] = []
        self._clock = node.clock
        node.create_subscription(msg_type, topic, lambda m: self.items.append((m, self._clock.epoch_now())), qos)

    @property
    def messages(self) -> list[Any]:
        return [m for m, _ in self.items]


async def nextage_cell(clock: Clock) -> tuple[LocalTransport, NextageSimBackend, BridgeNode]:
    transport = LocalTransport(clock)
    # random joint values pass through the robot's own body: this is about tf, not collisions
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN, extra={"collision_check": "off"}))
    assert isinstance(backend, NextageSimBackend)
    bridge = BridgeNode(transport.create_node("nextage_sim_bridge"), backend)
    await bridge.start()
    return transport, backend, bridge


def test_the_urdf_reaches_a_late_subscriber_once(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[str]:
        transport, _, bridge = await nextage_cell(clock)
        await clock.sleep(2.0)
        inbox = Inbox(transport.create_node("rviz"), String, ROBOT_DESCRIPTION_TOPIC, ROBOT_DESCRIPTION)
        await clock.sleep(1.0)
        await bridge.close()
        return [m.data for m in inbox.messages]

    assert run_sim(main) == [NEXTAGE_URDF.read_text(encoding="utf-8")]


def test_tf_places_every_link_and_composes_to_the_bridges_tcp_pose(run_sim: Any) -> None:
    rng = np.random.default_rng(7)
    model = UrdfTree(NEXTAGE_URDF.read_text(encoding="utf-8"))
    targets = []
    for _ in range(3):  # random joint values inside the limits of every group
        targets.append({g.name: tuple(float(rng.uniform(j.lower, j.upper)) * 0.8 for j in g.joints) for g in NEXTAGE_OPEN.groups})

    async def main(clock: Clock) -> list[tuple[TFMessage, list[TFMessage], JointState, dict[str, tuple[Pose, Pose]]]]:
        transport, backend, bridge = await nextage_cell(clock)
        viewer = transport.create_node("rviz")
        tf, tf_static = Inbox(viewer, TFMessage, TF_TOPIC, TF), Inbox(viewer, TFMessage, TF_STATIC_TOPIC, TF_STATIC)
        joints = Inbox(viewer, JointState, JOINT_STATES, SENSOR)
        seen = []
        for target in targets:
            moves = [backend.execute(g, MoveJoints(positions=q, joint_names=NEXTAGE_OPEN.group(g).joint_names)) for g, q in target.items()]
            for move in moves:
                await move
            await clock.sleep(0.2)  # a few state periods: the robot stands still
            # the bridge's TCP, and the tool it adds to the flange link (a back-end setting, not in the URDF)
            tcp = {g: (backend.tcp_pose(g), backend.model.arms[g].tool) for g in NEXTAGE_OPEN.arm_groups}
            seen.append((tf.messages[-1], tf_static.messages, joints.messages[-1], tcp))
        stamps_ok = all(abs(m.transforms[0].header.stamp.to_seconds() - t) < 1e-6 for m, t in tf.items)
        await bridge.close()
        assert stamps_ok  # stamped with the node's ROS time when published (delivered at once here)
        return seen  # type: ignore[return-value]

    for (last, static, state, tcp), target in zip(run_sim(main), targets):
        assert static == []  # the Nextage URDF has no fixed joint
        assert {t.child_frame_id for t in last.transforms} == set(model.links) - {"WAIST"}
        assert {t.header.stamp for t in last.transforms} == {state.header.stamp}  # tf and joint_states in step
        tree = tree_of(last.transforms)
        for link in model.links:
            assert compose_to_root(tree, link)[0] == "WAIST"
        for group, prefix in (("left_arm", "LARM"), ("right_arm", "RARM")):
            _, flange = compose_to_root(tree, f"{prefix}_JOINT5_Link")
            reported, tool = tcp[group]
            assert flange.compose(tool).distance_to(reported) < 1e-9 and flange.compose(tool).angle_to(reported) < 1e-7
        chest = tree["CHEST_JOINT0_Link"][1]
        assert math.isclose(chest.rpy()[2], target["torso_head"][0], abs_tol=1e-9)


def test_fixed_joints_go_once_on_tf_static_and_tf_carries_the_named_movable_joints(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[TFMessage], list[TFMessage]]:
        transport = LocalTransport(clock)
        publisher = RobotStatePublisher(transport.create_node("bridge"), SMALL_URDF)
        viewer = transport.create_node("viewer")
        tf, static = Inbox(viewer, TFMessage, TF_TOPIC, TF), Inbox(viewer, TFMessage, TF_STATIC_TOPIC, TF_STATIC)
        for _ in range(3):
            publisher.publish(("j1", "j2", "p", "not_in_the_urdf"), (math.pi / 2, 3.0, 0.25, 1.0), Time(5, 0))
            await clock.sleep(0.1)
        publisher.publish(("j1",), (0.0,), Time(6, 0))
        await clock.sleep(0.1)
        return tf.messages, static.messages

    tf, static = run_sim(main)
    assert len(static) == 1 and [(t.header.frame_id, t.child_frame_id) for t in static[0].transforms] == [("l1", "tool0")]
    flange = tree_of(static[0].transforms)["tool0"][1]
    assert flange.distance_to(Pose(0.1, 0, 0)) < 1e-12 and flange.angle_to(Pose.from_xyz_rpy(0, 0, 0, 0, math.pi / 2, 0)) < 1e-9
    placed = tree_of(tf[0].transforms)
    assert set(placed) == {"l1", "l2", "slide"} and {t.header.stamp for t in tf[0].transforms} == {Time(5, 0)}
    assert placed["l1"] == ("base", placed["l1"][1]) and placed["l1"][1].angle_to(Pose.from_xyz_rpy(0, 0, 0.3, 0, 0, math.pi / 2)) < 1e-9
    assert placed["l1"][1].distance_to(Pose(0, 0, 0.3)) < 1e-12
    assert placed["l2"][1].distance_to(Pose(0, 0.2, 0)) < 1e-12 and placed["l2"][1].angle_to(Pose.from_xyz_rpy(0, 0, 0, 0, 3.0, 0)) < 1e-9
    assert placed["slide"][1].distance_to(Pose(0.25, 0, 0)) < 1e-12
    assert set(tree_of(tf[-1].transforms)) == {"l1"}  # a joint the state does not name is left out


def test_tf_follows_every_joint_state_whichever_joints_moved(run_sim: Any) -> None:
    """A joint at rest keeps its transform from before (it is not worked out again); every published
    set equals the tree's own kinematics for that state, whichever joints moved since the last."""
    rng = np.random.default_rng(5)
    tree = UrdfTree(NEXTAGE_URDF.read_text())
    names = tree.movable_joints
    states = [rng.uniform(-1.0, 1.0, len(names))]
    for _ in range(12):  # now one joint moves, now several, now none
        state = states[-1].copy()
        moving = rng.choice(len(names), size=int(rng.integers(0, 4)), replace=False)
        state[moving] = rng.uniform(-1.0, 1.0, len(moving))
        states.append(state)

    async def main(clock: Clock) -> list[TFMessage]:
        transport = LocalTransport(clock)
        publisher = RobotStatePublisher(transport.create_node("bridge"), NEXTAGE_URDF.read_text())
        tf = Inbox(transport.create_node("viewer"), TFMessage, TF_TOPIC, TF)
        for k, state in enumerate(states):
            publisher.publish(names, tuple(state), Time(k, 0))
            await clock.sleep(0.05)
        return tf.messages

    published = run_sim(main)
    assert len(published) == len(states)
    for message, state in zip(published, states):
        expected = {j.child: (j.parent, pose) for j, pose in tree.movable_transforms(names, tuple(state))}
        got = tree_of(message.transforms)
        assert set(got) == set(expected)
        for child, (parent, pose) in expected.items():
            q, want = got[child][1], pose
            assert got[child][0] == parent and q.distance_to(want) < 1e-12, child
            assert max(abs(a - b) for a, b in zip((q.qx, q.qy, q.qz, q.qw), (want.qx, want.qy, want.qz, want.qw))) < 1e-12, child


def test_a_backend_without_urdf_publishes_neither(run_sim: Any) -> None:
    async def main(clock: Clock) -> int:
        transport = LocalTransport(clock)
        viewer = transport.create_node("viewer")
        inboxes = [
            Inbox(viewer, String, ROBOT_DESCRIPTION_TOPIC, ROBOT_DESCRIPTION),
            Inbox(viewer, TFMessage, TF_TOPIC, TF),
            Inbox(viewer, TFMessage, TF_STATIC_TOPIC, TF_STATIC),
        ]
        bridge = BridgeNode(transport.create_node("bridge"), ScriptedBackend(clock, NEXTAGE_OPEN))
        await bridge.start()
        await clock.sleep(0.5)
        await bridge.close()
        return sum(len(i.items) for i in inboxes)

    assert run_sim(main) == 0


def test_the_world_frames_agree_robot_urdf_root_and_backends() -> None:
    assert UrdfTree(NEXTAGE_URDF.read_text(encoding="utf-8")).root == NEXTAGE_OPEN.world_frame == NextageSimBackend.world_frame
    assert VPlusBackend.world_frame == ADEPT_VIPER_S850.world_frame
    assert KukaRsiBackend.world_frame == KUKA_KR.world_frame


def test_setup_installs_the_urdf_under_share_and_keeps_it_as_package_data(monkeypatch: pytest.MonkeyPatch) -> None:
    captured: dict[str, Any] = {}
    monkeypatch.setattr(setuptools, "setup", lambda **kwargs: captured.update(kwargs))
    runpy.run_path(str(ROOT / "setup.py"))
    installed = dict(captured["data_files"])
    assert "robot_bridges/nextage_sim/urdf/nextage_open.urdf" in installed["share/dual_arm_executive/urdf"]
    assert all((ROOT / path).is_file() for path in installed["share/dual_arm_executive/urdf"])
    assert "urdf/*.urdf" in captured["package_data"]["robot_bridges.nextage_sim"]
