"""robot_state_publisher's messages for one URDF: ``tf_static`` once, ``tf`` for each joint state.

Two places make them and must make the same: the bridge's
:class:`~robot_bridges.robot_state.RobotStatePublisher`, for whoever listens to ``tf`` (RViz,
Foxglove), and the flight recorder's encoder process, which works ``tf`` out of the recorded
``joint_states`` and ``robot_description`` instead of having the bridge compute and hand over
some 15 transforms 20 times a second on the control path.  One class serves both, so a recorded
``tf`` is the one a listener would have got, message for message.

A joint's transform depends on its own position only, so a joint at rest keeps the Transform it
had; pinocchio's forward kinematics run only when some joint moved.
"""
from __future__ import annotations

from collections.abc import Sequence

from core_functions.urdf_tree import UrdfTree
from node_transport.msgs import Header, Quaternion, TFMessage, Time, Transform, TransformStamped, Vector3
from node_transport.transforms import transform_stamped


class LinkTransforms:
    """The link transforms of one URDF as ``tf`` and ``tf_static`` messages."""

    def __init__(self, urdf: str) -> None:
        self.tree = UrdfTree(urdf)
        self._placed: dict[str, tuple[float, Transform]] = {}  # movable joint -> (position, its transform)

    def fixed(self, stamp: Time) -> TFMessage | None:
        """Every fixed joint in one message (``tf_static`` is latched: sent once); None when there is none."""
        fixed = self.tree.fixed_transforms()
        return TFMessage(tuple(transform_stamped(j.parent, j.child, p, stamp) for j, p in fixed)) if fixed else None

    def moving(self, names: Sequence[str], positions: Sequence[float], stamp: Time) -> TFMessage:
        """One transform per movable joint the state names, stamped like the state (ValueError
        when names and positions differ in length)."""
        given = self.tree.positions(names, positions)
        if any(self._placed.get(name, (None,))[0] != value for name, value in given.items()):
            self.tree.place(given)
        transforms = []
        for joint in self.tree.joints:
            value = given.get(joint.name)
            if value is None:
                continue
            placed = self._placed.get(joint.name)
            if placed is None or placed[0] != value:
                translation, rotation = self.tree.relative(joint)
                placed = self._placed[joint.name] = (value, Transform(Vector3(*translation), Quaternion(*rotation)))
            transforms.append(TransformStamped(Header(stamp, joint.parent), joint.child, placed[1]))
        return TFMessage(tuple(transforms))
