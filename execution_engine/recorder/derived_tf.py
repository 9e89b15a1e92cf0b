"""``tf`` worked out in the encoder process from the recorded ``joint_states`` and ``robot_description``.

The bridge publishes ``tf`` only when someone listens, and a recorder listening to it would make
the bridge compute about 15 transforms 20 times a second and hand each over, object by object,
on the control path: at ``--speed max`` that alone cost the run some 14 % of its CPU time.  In
an in-process run (``run --record``) the bridge's ``tf`` is a pure function of its own
``joint_states`` and URDF, stamped like the state and published in the same step; so the
recorder asks the encoder to do what the bridge would have done, with the same code
(:class:`~node_transport.link_transforms.LinkTransforms`), and writes each ``tf``
message right after its joint state, with the same log time.  A recording made this way holds
the ``tf`` a listener would have received, message for message.
"""
from __future__ import annotations

import dataclasses
from typing import Any

from execution_engine.recorder.frames import ros_fields
from node_transport.msgs import TFMessage, Time
from node_transport.qos import QoS

TF_TYPE = TFMessage.ROS_TYPE


_FIELD_NAMES: dict[type, tuple[str, ...] | None] = {}  # class -> its fields (None: not a message), asked once


def message_fields(value: Any) -> Any:
    """A message object as the CDR encoder takes it: dicts of fields, lists for sequences.
    (About 90 objects a ``tf`` message, 20 times a second: the class is looked at once.)"""
    cls = type(value)
    names = _FIELD_NAMES.get(cls, ())
    if names == ():
        names = _FIELD_NAMES[cls] = tuple(f.name for f in dataclasses.fields(cls)) if dataclasses.is_dataclass(cls) else None
    if names is not None:  # the same form the run's process pickles messages into (frames.ros_fields)
        return ros_fields({name: message_fields(getattr(value, name)) for name in names})
    if cls is tuple or cls is list:
        return [message_fields(v) for v in value]
    return value


@dataclasses.dataclass
class DerivedTf:
    """Which topics ``tf`` comes from, and the URDF's link transforms once its text arrived."""

    topic: str
    offered: tuple[QoS, ...]
    joint_states: str
    description: str
    #: description topic -> its URDF's LinkTransforms: ``robot_description``, and in a cell of several robots each
    #: robot's ``<robot>/robot_description`` beside it (each bridge publishes its robot's, robot_state.py)
    links: dict[str, Any] = dataclasses.field(default_factory=dict)

    def describes(self, topic: str) -> bool:
        """Whether ``topic`` carries a URDF this recording works ``tf`` out of: ``robot_description`` or,
        in the same namespace, a robot's ``<robot>/robot_description``."""
        if topic == self.description:
            return True
        namespace = self.description[: -len("robot_description")]
        return topic.startswith(namespace) and topic.endswith("/robot_description") and "/" not in topic[len(namespace):-len("/robot_description")]

    def follow(self, topic: str, msg: dict[str, Any]) -> dict[str, Any] | None:
        """After a recorded message: the ``tf`` message it implies, or None.

        A URDF pinocchio cannot read, or a joint state whose names and positions differ in
        length, gives no ``tf`` -- the bridge could not have published one either.  With several
        robots' URDFs, a joint state gives the ``tf`` of the robots whose joints it names (each
        bridge publishes its own robot's joint states, then its tf)."""
        if self.describes(topic):
            from node_transport.link_transforms import LinkTransforms  # pinocchio is slow to load: only when asked

            try:
                self.links[topic] = LinkTransforms(str(msg.get("data", "")))
            except (ValueError, RuntimeError):
                self.links.pop(topic, None)
            return None
        if topic != self.joint_states or not self.links:
            return None
        stamp = msg["header"]["stamp"]
        try:
            messages = [links.moving(msg["name"], msg["position"], Time(int(stamp["sec"]), int(stamp["nanosec"]))) for links in self.links.values()]
        except ValueError:
            return None
        if len(messages) == 1:
            return message_fields(messages[0])  # one robot: its message, as its bridge publishes it even when empty
        moved = [m for m in messages if m.transforms]
        if not moved:
            return None
        return message_fields(moved[0] if len(moved) == 1 else TFMessage(tuple(t for m in moved for t in m.transforms)))
