"""The compiled CDR codec writes and reads exactly what cyclonedds-python does, for every interface type.

What a ROS 2 peer, the recorder or the studio receives from the DDS transport must not change with
the codec (issue 22): for each type of the project's and the standard interface files, random
samples encode to cyclonedds's bytes (header and padding included) and decode back to the sample
cyclonedds decodes; bytes that are not such a sample are refused with an exception, never a
sample of another shape.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("cyclonedds")

from node_transport.dds_cdr import CdrCodec, CdrError, FallbackCodec, codec  # noqa: E402
from node_transport.idl import InterfaceRegistry  # noqa: E402

REGISTRY = InterfaceRegistry()


def _all_wire_types() -> list[type]:
    """Every message, service (with rmw's request header) and action type of the interface folders."""
    found: dict[str, type] = {}
    for root in REGISTRY.roots:
        for path in sorted(Path(root).glob("*/*/*")):
            package, kind, name = path.parts[-3], path.parts[-2], path.stem
            if kind == "msg" and path.suffix == ".msg":
                found[f"{package}/msg/{name}"] = REGISTRY.message(f"{package}/msg/{name}")
            elif kind == "srv" and path.suffix == ".srv":
                request, reply = REGISTRY.wire_service(f"{package}/srv/{name}")
                found[f"{package}/srv/{name}#request"], found[f"{package}/srv/{name}#reply"] = request, reply
            elif kind == "action" and path.suffix == ".action":
                for part, cls in REGISTRY.wire_action(f"{package}/action/{name}").items():
                    found[f"{package}/action/{name}#{part}"] = cls
    return [found[key] for key in sorted(found)]


WIRE_TYPES = _all_wire_types()
_INTS = {"b": (-(1 << 7), (1 << 7) - 1), "B": (0, (1 << 8) - 1), "h": (-(1 << 15), (1 << 15) - 1), "H": (0, (1 << 16) - 1),
         "i": (-(1 << 31), (1 << 31) - 1), "I": (0, (1 << 32) - 1), "q": (-(1 << 63), (1 << 63) - 1), "Q": (0, (1 << 64) - 1)}


def _primitive(code: str) -> st.SearchStrategy[Any]:
    if code == "?":
        return st.booleans()
    if code == "f":
        return st.floats(width=32, allow_nan=False)
    if code == "d":
        return st.floats(allow_nan=False)
    low, high = _INTS[code]
    return st.integers(low, high)


def values(machine: Any) -> st.SearchStrategy[Any]:
    """Samples of the type a cyclonedds machine reads and writes (small sequences and strings)."""
    kind = type(machine).__name__
    if kind == "PrimitiveMachine":
        return _primitive(machine.code)
    if kind == "StringMachine":
        return st.text(max_size=machine.bound or 12)
    if kind == "ByteArrayMachine":
        return st.binary(min_size=machine.size, max_size=machine.size)
    if kind == "PlainCdrV2ArrayOfPrimitiveMachine":
        return st.lists(_primitive(machine.code[-1]), min_size=machine.length, max_size=machine.length)
    if kind == "PlainCdrV2SequenceOfPrimitiveMachine":
        return st.lists(_primitive(machine.code), max_size=min(machine.max_length or 5, 5))
    if kind == "SequenceMachine":
        return st.lists(values(machine.submachine), max_size=min(machine.maxlen or 3, 3))
    if kind == "ArrayMachine":
        return st.lists(values(machine.submachine), min_size=machine.size, max_size=machine.size)
    if kind == "InstanceMachine":
        return samples(machine.type)
    raise AssertionError(f"a machine the interface files do not make: {kind}")


def samples(cls: type) -> st.SearchStrategy[Any]:
    idl = cls.__idl__  # type: ignore[attr-defined]
    idl.populate()
    members = idl.v1_machine.members_machines
    return st.builds(cls, **{name: st.deferred(lambda m=m: values(m)) for name, m in members.items()})


def _theirs(sample: Any) -> bytes:
    data: bytes = sample.serialize(use_version_2=False)
    return data + bytes(-len(data) & 3)


def test_every_interface_type_is_compiled() -> None:
    """No type of the interface folders falls back to cyclonedds's serializer."""
    assert len(WIRE_TYPES) > 60
    assert [cls.__name__ for cls in WIRE_TYPES if not isinstance(codec(cls), CdrCodec)] == []


@settings(max_examples=300)
@given(st.sampled_from(WIRE_TYPES).flatmap(samples))
def test_bytes_are_cyclonedds_bytes(sample: Any) -> None:
    ours = codec(type(sample)).encode(sample)
    assert ours == _theirs(sample)
    assert codec(type(sample)).decode(ours) == type(sample).deserialize(ours) == sample


@given(st.sampled_from(WIRE_TYPES).flatmap(samples), st.data())
def test_cut_or_damaged_samples_are_refused_or_read_as_cyclonedds_reads_them(sample: Any, data: st.DataObject) -> None:
    """A sample cut short raises; flipped bytes either raise or decode as cyclonedds decodes them
    (Cyclone's C layer checks a received sample's lengths before Python sees it; this is the rest)."""
    good = codec(type(sample)).encode(sample)
    cut = data.draw(st.integers(4, len(good) - 1)) if len(good) > 4 else 4
    body = good[:cut]
    try:
        decoded = codec(type(sample)).decode(body)
    except Exception:  # noqa: BLE001 - refused: what the Taker counts as rejected
        decoded = None
    if decoded is not None:  # only trailing padding was cut: the same sample
        assert decoded == sample
    position = data.draw(st.integers(4, len(good) - 1)) if len(good) > 4 else None
    if position is not None:
        flipped = bytearray(good)
        flipped[position] ^= data.draw(st.integers(1, 255))
        try:
            ours = codec(type(sample)).decode(bytes(flipped))
        except Exception:  # noqa: BLE001
            return
        assert repr(ours) == repr(type(sample).deserialize(bytes(flipped)))  # repr: a flipped byte may make a NaN


def test_a_value_the_type_cannot_carry_is_refused_naming_the_field() -> None:
    gid = REGISTRY.message("rmw_dds_common/msg/Gid")
    with pytest.raises(CdrError, match="data: an array of 16 octets"):
        codec(gid).encode(gid(data=[1, 2, 3]))
    status = REGISTRY.message("builtin_interfaces/msg/Time")
    with pytest.raises(Exception, match="argument out of range|format requires"):
        codec(status).encode(status(sec=1 << 40, nanosec=0))


def test_other_encodings_are_read_by_cyclonedds() -> None:
    """A big-endian peer's sample (encapsulation CDR_BE) is not misread as little endian."""
    string = REGISTRY.message("std_msgs/msg/String")
    big = b"\x00\x00\x00\x00" + (4).to_bytes(4, "big") + b"abc\x00"
    assert codec(string).decode(big) == string.deserialize(big) == string(data="abc")


def test_fallback_writes_cyclonedds_bytes() -> None:
    string = REGISTRY.message("std_msgs/msg/String")
    sample = string(data="hello")
    assert FallbackCodec(string).encode(sample) == _theirs(sample)
    assert FallbackCodec(string).decode(_theirs(sample)) == sample
