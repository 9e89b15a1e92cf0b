"""robot_state_publisher, inside the bridge: the URDF on ``robot_description``, the links on ``tf``.

RViz and Foxglove draw a robot from its URDF (``robot_description``, latched) and the pose of
every link (``tf``, ``tf_static``).  A ROS cell would normally add robot_state_publisher for
that; the bridge already knows both the URDF (its back end's :meth:`robot_description`) and the
joint positions it publishes on ``joint_states``, so it publishes the transforms itself, from
the same positions and with the same stamp -- no extra node, and no moment where the drawn arm
and ``joint_states`` disagree.

As robot_state_publisher: one transform per movable URDF joint (parent link -> child link) with
every joint-state publication; the fixed joints once on ``tf_static``; the URDF text once,
latched.  In a cell of several robots each robot's bridge does so for its robot, placed
(:mod:`robot_bridges.placed_urdf`): its URDF on ``/<robot>/robot_description`` (as one
robot_state_publisher per robot namespace would), its base on ``tf_static`` from the cell's
``world``, its links under the cell's prefix.  The kinematics are pinocchio's (:mod:`core_functions.urdf_tree`), loaded only for a
back end that has a URDF.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from core_functions.geometry import Pose
from node_transport.msgs import String, TFMessage, Time
from node_transport.port import Node, Publisher
from node_transport.transforms import transform_stamped
from node_transport.qos import ROBOT_DESCRIPTION, TF, TF_STATIC
from node_transport.wire import ROBOT_DESCRIPTION_TOPIC, TF_STATIC_TOPIC, TF_TOPIC
from robot_bridges.placed import PlacedBackend

if TYPE_CHECKING:
    from core_functions.urdf_tree import UrdfTree
    from robot_bridges.backend import RobotBackend


class RobotStatePublisher:
    """Publishes one robot's URDF and link transforms through ``node``."""

    def __init__(self, node: Node, urdf: str, description_topic: str = ROBOT_DESCRIPTION_TOPIC) -> None:
        from node_transport.link_transforms import LinkTransforms  # pinocchio is slow to load: only for a robot with a URDF

        self.node = node
        self.links = LinkTransforms(urdf)
        self.tree: UrdfTree = self.links.tree
        self._description = node.create_publisher(String, description_topic, ROBOT_DESCRIPTION)
        self._tf = node.create_publisher(TFMessage, TF_TOPIC, TF)
        self._tf_static = node.create_publisher(TFMessage, TF_STATIC_TOPIC, TF_STATIC)
        self._description.publish(String(urdf))
        self._static_sent = False

    @classmethod
    def for_backend(cls, node: Node, backend: RobotBackend) -> RobotStatePublisher | None:
        """The publisher for ``backend``'s URDF, or None when the back end knows no URDF.  A robot of a cell of
        several (placed) publishes its URDF on ``/<robot>/robot_description``, rooted at the cell's ``world`` and
        under the cell's prefix; its links go on the one ``tf`` and ``tf_static`` with every other robot's."""
        urdf = backend.robot_description()
        if urdf is None:
            return None
        return cls(node, urdf, backend.description_topic) if isinstance(backend, PlacedBackend) else cls(node, urdf)

    def publish(self, names: Sequence[str], positions: Sequence[float], stamp: Time) -> None:
        """The transforms for one joint state, stamped like it; the fixed joints the first time."""
        if not self._static_sent:
            self._static_sent = True
            fixed = self.links.fixed(stamp)
            if fixed is not None:
                self._tf_static.publish(fixed)
        if self._tf.get_subscription_count() == 0:
            return  # nobody draws the robot (a recording works tf out of joint_states itself): skip the kinematics
        self._tf.publish(self.links.moving(names, positions, stamp))


def publish_mount(node: Node, backend: RobotBackend) -> Publisher[TFMessage] | None:
    """For a placed robot whose URDF and links its own driver publishes (a ros2-control robot: its
    robot_state_publisher, under the driver's names): the cell's world -> the driver's root link at the
    robot's base, once on ``tf_static``, so the driver's drawing stands where the cell places the robot.
    None (nothing published) for another back end, or a driver's URDF rooted at the world frame itself
    (its links then hang from the cell's origin: the bridge says so once)."""
    if not isinstance(backend, PlacedBackend) or backend.inner.robot_description() is not None:
        return None
    root = backend.inner.world_frame
    if root == backend.world_frame:
        if backend.base != Pose():
            node.logger.warning("%s: the robot's links are rooted at %r, the cell's world frame itself: tf shows the robot at the cell's "
                                "origin, not at its base (a driver's URDF rooted at its own base link stands where the cell places it)",
                                node.fully_qualified_name, root)
        return None
    publisher = node.create_publisher(TFMessage, TF_STATIC_TOPIC, TF_STATIC)
    publisher.publish(TFMessage((transform_stamped(backend.world_frame, root, backend.base, node.now_stamp()),)))
    return publisher
