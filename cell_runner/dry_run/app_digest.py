"""The digest of an application as it was read: what a dry run runs, whatever file (or page, or goal) it came from.

A kept verdict must never be one of another application.  The file's bytes say what the file holds,
not what is run: the station runs the document on its page (saved or not), a RunApplication goal may
carry its XML in the goal, and an application's ``<call>`` includes bring operations from other
files.  So the key also holds this digest of the :class:`~execution_engine.app_model.model.Application`
itself -- every operation, call, parameter, zone, the cell's frames and elements, the robot model --
which is a function of what was read, and of nothing else.

Values are encoded by kind with their type's name (a dataclass by its fields that take part in its
equality: its caches do not), floats exactly (``float.hex``), mappings and sets in a sorted order.  A
value of a kind not listed here is :class:`NotDigestible`: no key, the dry run runs (never a key
that could miss a difference).
"""
from __future__ import annotations

import dataclasses
import enum
import hashlib
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

import numpy as np


class NotDigestible(TypeError):
    """A value the digest cannot encode faithfully: no key may be made from it."""


def app_digest(value: Any) -> str:
    """The hex SHA-256 of ``value``'s canonical encoding (:func:`encode`)."""
    return hashlib.sha256(encode(value)).hexdigest()


def encode(value: Any, depth: int = 0) -> bytes:
    """A byte string equal for equal values and different for different ones (of the kinds encoded)."""
    if depth > 200:
        raise NotDigestible("nested deeper than an application is")
    if value is None or isinstance(value, bool):
        return f"c{value!r};".encode()
    if isinstance(value, enum.Enum):
        return b"e" + _text(type(value).__qualname__) + encode(value.value, depth + 1)
    if isinstance(value, int):
        return f"i{value};".encode()
    if isinstance(value, float):
        return f"f{value.hex()};".encode()
    if isinstance(value, str):
        return b"s" + _text(value)
    if isinstance(value, bytes):
        return b"b" + _sized(value)
    if isinstance(value, PurePath):
        return b"p" + _text(str(value))
    if isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            raise NotDigestible("an array of objects")
        return b"a" + _text(value.dtype.str) + _text(repr(value.shape)) + _sized(np.ascontiguousarray(value).tobytes())
    if isinstance(value, np.generic):
        return encode(value.item(), depth + 1)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        parts = [encode(getattr(value, f.name), depth + 1) for f in dataclasses.fields(value) if f.compare]
        names = ",".join(f.name for f in dataclasses.fields(value) if f.compare)
        return b"d" + _text(f"{type(value).__module__}.{type(value).__qualname__}({names})") + _joined(parts)
    if isinstance(value, Mapping):
        items = sorted((encode(k, depth + 1), encode(v, depth + 1)) for k, v in value.items())
        return b"m" + _joined([k + v for k, v in items])
    if isinstance(value, (tuple, list)):
        return (b"t" if isinstance(value, tuple) else b"l") + _joined([encode(v, depth + 1) for v in value])
    if isinstance(value, (set, frozenset)):
        return b"u" + _joined(sorted(encode(v, depth + 1) for v in value))
    raise NotDigestible(f"a {type(value).__module__}.{type(value).__qualname__}")


def _text(text: str) -> bytes:
    return _sized(text.encode("utf-8", "surrogatepass"))


def _sized(data: bytes) -> bytes:
    return f"{len(data)}:".encode() + data


def _joined(parts: list[bytes]) -> bytes:
    return f"{len(parts)}[".encode() + b"".join(parts) + b"]"
