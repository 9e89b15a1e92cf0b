"""What the run's process and the recording's encoder process (:mod:`.encoder`) pass each other:
frames of a one-byte kind, a 4-byte little-endian length and a payload, and messages pickled by
their fields.  Kept apart from the encoder so the run's process loads neither ``mcap`` nor
``mcap-ros2-support``.
"""
from __future__ import annotations

import dataclasses
import io
import pickle
import struct
from typing import IO, Any

HEAD = struct.Struct("<cI")


def frame(kind: bytes, payload: bytes) -> bytes:
    return HEAD.pack(kind, len(payload)) + payload


def read_frame(stream: IO[bytes]) -> tuple[bytes, bytes] | None:
    """The next frame, None at the end of the stream (or in the middle of a frame: the writer died)."""
    head = stream.read(HEAD.size)
    if len(head) < HEAD.size:
        return None
    kind, size = HEAD.unpack(head)
    payload = stream.read(size)
    return (kind, payload) if len(payload) == size else None


def ros_fields(fields: dict[str, Any]) -> dict[str, Any]:
    """A message as the CDR encoder takes it, from the fields the run's process pickled
    (:class:`MessagePickler`): nested messages arrive as dicts already; sequences become lists,
    and a ROS ``byte`` (bytes of length 1 in the mirrors) an int.  A ``uint8[]`` buffer
    (``ByteBuffer``, image data) stays bytes: the encoder takes it whole."""
    for name, value in fields.items():
        cls = type(value)
        if cls is tuple:
            fields[name] = list(value)
        elif cls is bytes and len(value) == 1:
            fields[name] = value[0]
    return fields


class MessagePickler(pickle.Pickler):
    """Pickles a message by its fields, not its class: the mirrors of the project's own ``.msg``
    types are made at run time and could not be found by name in the encoder process.  A message
    arrives there as the dict of its fields (:func:`ros_fields`), as the encoder wants it."""

    _messages: dict[type, bool] = {}  # class -> whether it is a message (asked once: an enum class answers slowly)

    def reducer_override(self, obj: Any) -> Any:
        cls = type(obj)
        message = self._messages.get(cls)
        if message is None:
            message = self._messages[cls] = isinstance(getattr(cls, "ROS_TYPE", None), str) and dataclasses.is_dataclass(cls)
        if not message:
            return NotImplemented
        try:
            fields = obj.__dict__
        except AttributeError:  # a dataclass with slots
            fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
        return ros_fields, (fields,)


def pickled(items: list[tuple[Any, ...]]) -> bytes:
    buffer = io.BytesIO()
    MessagePickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(items)
    return buffer.getvalue()
