"""What RViz or Foxglove sees of a cell of several robots, collected and checked: each robot's URDF on
``/<robot>/robot_description``, ``/joint_states``, ``/tf_static``, ``/tf`` and the bridges' ``/<group>/tcp_pose``.

Shared by the in-process check (``run``'s bridges on one local transport) and the one over DDS (``launch``'s
bridge processes), so both are held to the same picture: every robot's URDF parses with the project's URDF
library, its movable joints exactly the names its bridge puts on /joint_states; the tf tree is one, rooted at the
cell's ``world``; the chain from ``world`` to each group's TCP link (and the back end's documented tool on it)
is the TCP pose the bridge reports at the same stamp.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from core_functions.cell_robots import CellRobot, CellRobotModel
from core_functions.geometry import Pose
from core_functions.urdf_tree import UrdfTree
from node_transport.msgs import JointState, PoseStamped, String, TFMessage, TransformStamped
from node_transport.port import Node
from node_transport.qos import JOINT_STATES, ROBOT_DESCRIPTION, SENSOR, Durability, History, QoS, Reliability
from node_transport.transforms import compose_to_root, tree_of
from robot_bridges.nextage_sim.backend import HAND_TOOL

#: as tf2_ros's StaticListenerQoS: transient local and deep, so every broadcaster's latched message is kept
TF_STATIC_LISTENER = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 100)
TF_LISTENER = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 100)
#: how far a back end's reported TCP may lie from its joints' forward kinematics (m, rad): a V+ controller
#: reports joints (deg) and TCP (mm, deg) separately in three decimals (vplus/codec.py), ~1e-5 m apart at the
#: flange; the others report both from one set of joints.  Far below a wrong base, prefix or link (centimetres).
TCP_TOLERANCE: dict[str, float] = {"vplus": 5e-5, "kuka-rsi": 1e-9, "nextage-sim": 1e-9}
#: each back end's TCP: the URDF link it is computed on and the tool pose on that link
TCP_LINKS: dict[str, dict[str, tuple[str, Pose]]] = {
    "kuka-rsi": {"arm": ("tool0", Pose())},
    "vplus": {"arm": ("flange", Pose())},
    "nextage-sim": {"left_arm": ("LARM_JOINT5_Link", HAND_TOOL), "right_arm": ("RARM_JOINT5_Link", HAND_TOOL)},
}


def description_topic(robot: CellRobot) -> str:
    return f"/{robot.name}/robot_description"


@dataclass
class Picture:
    """Everything a ROS viewer is sent, as it arrives."""

    descriptions: dict[str, str] = field(default_factory=dict)
    states: list[JointState] = field(default_factory=list)
    static: list[TFMessage] = field(default_factory=list)
    tf: list[TFMessage] = field(default_factory=list)
    tcp: dict[str, list[PoseStamped]] = field(default_factory=dict)

    def listen(self, node: Node, robot: CellRobotModel) -> None:
        for member in robot.members:
            topic = description_topic(member)
            node.create_subscription(String, topic, lambda m, t=topic: self.descriptions.__setitem__(t, m.data), ROBOT_DESCRIPTION)
        node.create_subscription(JointState, "/joint_states", self.states.append, JOINT_STATES)
        node.create_subscription(TFMessage, "/tf_static", self.static.append, TF_STATIC_LISTENER)
        node.create_subscription(TFMessage, "/tf", self.tf.append, TF_LISTENER)
        for group in robot.group_names:
            if tcp_link(robot, group) is not None:
                node.create_subscription(PoseStamped, f"/{group}/tcp_pose", self.tcp.setdefault(group, []).append, SENSOR)

    def complete(self, robot: CellRobotModel) -> bool:
        """Every robot's URDF, static transforms and moving links, every TCP, and a joint state of each robot."""
        named = {n for s in self.states for n in s.name}
        return (len(self.descriptions) == len(robot.members) and len(self.static) >= len(robot.members)
                and all(self.tcp.values()) and set(robot.joint_names) <= named
                and len({t.child_frame_id for m in self.tf for t in m.transforms}) >= movable_count(self.descriptions.values()))


def movable_count(descriptions: Iterable[str]) -> int:
    return sum(len(UrdfTree(d).movable_joints) for d in descriptions)


def tcp_link(robot: CellRobotModel, group: str) -> tuple[str, Pose] | None:
    """The cell's name of the link ``group``'s TCP is computed on, and the tool on it (None: a group without a TCP)."""
    member = robot.member_of(group)
    assert member is not None
    link = TCP_LINKS[member.backend].get(member.own_group(group))
    return None if link is None else (member.names.prefix + link[0], link[1])


def same(a: Pose, b: Pose, tol: float) -> bool:
    return a.distance_to(b) < tol and a.angle_to(b) < 4 * tol


def check(picture: Picture, robot: CellRobotModel) -> None:
    """The picture a viewer needs of ``robot``'s cell (AssertionError naming what differs)."""
    by_robot_states: dict[str, set[str]] = {}
    for member in robot.members:
        urdf = picture.descriptions[description_topic(member)]
        tree = UrdfTree(urdf)  # the project's URDF library (pinocchio) parses it
        assert tree.root == "world", (member.name, tree.root)
        joints = set(tree.movable_joints)
        # the joint states of this robot's bridge: the messages that name its joints
        sent = {n for s in picture.states if set(s.name) & joints for n in s.name}
        assert joints == sent, (member.name, sorted(joints ^ sent))
        by_robot_states[member.name] = joints
    every = {n for s in picture.states for n in s.name}
    assert every == set().union(*by_robot_states.values()), ("a joint on /joint_states that no URDF has", sorted(every - set().union(*by_robot_states.values())))
    static: list[TransformStamped] = [t for m in picture.static for t in m.transforms]
    children = [t.child_frame_id for t in static]
    assert len(children) == len(set(children)), "a frame published twice on /tf_static"
    assert all(t.child_frame_id != "world" for t in static)
    for group, poses in picture.tcp.items():
        link = tcp_link(robot, group)
        assert link is not None
        checked = 0
        for reported in poses[-5:]:
            moving = [t for m in picture.tf for t in m.transforms if t.header.stamp == reported.header.stamp]
            if not moving:
                continue
            root, flange = compose_to_root(tree_of([*static, *moving]), link[0])
            assert root == "world", (group, root)
            p, q = reported.pose.position, reported.pose.orientation
            assert reported.header.frame_id == "world"
            tcp = Pose(p.x, p.y, p.z, q.x, q.y, q.z, q.w)
            member = robot.member_of(group)
            assert member is not None
            assert same(flange.compose(link[1]), tcp, TCP_TOLERANCE[member.backend]), (group, flange.compose(link[1]), tcp)
            checked += 1
        assert checked, f"no /tf at the stamp of a {group} tcp_pose"
