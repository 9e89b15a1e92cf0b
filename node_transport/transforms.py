"""Poses to tf messages and back: the one place that maps the project's poses onto ``tf``.

The bridge publishes the robot's links on ``tf`` / ``tf_static`` and the engine publishes the
cell's frames on ``tf_static``; both send a parent -> child :class:`Pose` (metres, unit
quaternion x y z w, REP 103) as a ``geometry_msgs/TransformStamped``, and tests read them back to
compose a chain.  Keeping the field mapping here means it is written once.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping

from core_functions.geometry import Pose
from node_transport.msgs import Header, Quaternion, Time, Transform, TransformStamped, Vector3


def transform_stamped(parent: str, child: str, pose: Pose, stamp: Time) -> TransformStamped:
    """``child`` placed at ``pose`` in ``parent``, as tf2 expects it."""
    return TransformStamped(
        header=Header(stamp=stamp, frame_id=parent),
        child_frame_id=child,
        transform=Transform(Vector3(pose.x, pose.y, pose.z), Quaternion(pose.qx, pose.qy, pose.qz, pose.qw)),
    )


def pose_of(transform: Transform) -> Pose:
    """The pose a transform carries (Pose refuses a quaternion that is not of unit length)."""
    t, r = transform.translation, transform.rotation
    return Pose(t.x, t.y, t.z, r.x, r.y, r.z, r.w)


def tree_of(transforms: Iterable[TransformStamped]) -> dict[str, tuple[str, Pose]]:
    """child -> (parent, pose in the parent) of a set of transforms; a later one for a child wins,
    as in a tf2 buffer."""
    return {t.child_frame_id: (t.header.frame_id, pose_of(t.transform)) for t in transforms}


def compose_to_root(tree: Mapping[str, tuple[str, Pose]], frame: str) -> tuple[str, Pose]:
    """(root, pose of ``frame`` in the root) by walking parents, as ``lookup_transform`` does.

    Raises ValueError on a cycle: a tf tree has none, so one here is a publisher's defect.
    """
    pose = Pose()
    seen = {frame}
    while frame in tree:
        parent, local = tree[frame]
        pose = local.compose(pose)
        if parent in seen:
            raise ValueError(f"the tf tree has a cycle through {parent!r}")
        seen.add(parent)
        frame = parent
    return frame, pose
