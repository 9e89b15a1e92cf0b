"""robot_state_publisher, inside the bridge: the URDF on ``robot_description``, the links on ``tf``.

RViz and Foxglove draw a robot from its URDF (``robot_description``, latched) and the pose of
every link (``tf``, ``tf_static``).  A ROS cell would normally add robot_state_publisher for
that; the bridge already knows both the URDF (its back end's :meth:`robot_description`) and the
joint positions it publishes on ``joint_states``, so it publishes the transforms itself, from
the same positions and with the same stamp -- no extra node, and no moment where the drawn arm
and ``joint_states`` disagree.

As robot_state_publisher: one transform per movable URDF joint (parent link -> child link) with
every joint-state publication; the fixed joints once on ``tf_static``; the URDF text once,
latched.  The kinematics are pinocchio's (:mod:`core_functions.urdf_tree`), loaded only for a
back end that has a URDF.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from node_transport.msgs import String, TFMessage, Time
from node_transport.port import Node
from node_transport.qos import ROBOT_DESCRIPTION, TF, TF_STATIC
from node_transport.wire import ROBOT_DESCRIPTION_TOPIC, TF_STATIC_TOPIC, TF_TOPIC

if TYPE_CHECKING:
    from core_functions.urdf_tree import UrdfTree
    from robot_bridges.backend import RobotBackend


class RobotStatePublisher:
    """Publishes one robot's URDF and link transforms through ``node``."""

    def __init__(self, node: Node, urdf: str) -> None:
        from node_transport.link_transforms import LinkTransforms  # pinocchio is slow to load: only for a robot with a URDF

        self.node = node
        self.links = LinkTransforms(urdf)
        self.tree: UrdfTree = self.links.tree
        self._description = node.create_publisher(String, ROBOT_DESCRIPTION_TOPIC, ROBOT_DESCRIPTION)
        self._tf = node.create_publisher(TFMessage, TF_TOPIC, TF)
        self._tf_static = node.create_publisher(TFMessage, TF_STATIC_TOPIC, TF_STATIC)
        self._description.publish(String(urdf))
        self._static_sent = False

    @classmethod
    def for_backend(cls, node: Node, backend: RobotBackend) -> RobotStatePublisher | None:
        """The publisher for ``backend``'s URDF, or None when the back end knows no URDF."""
        urdf = backend.robot_description()
        return None if urdf is None else cls(node, urdf)

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
