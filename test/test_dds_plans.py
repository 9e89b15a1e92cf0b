"""The compiled conversion between mirrors and DDS samples answers what the general one answers.

The DDS transport converts a whole message by code compiled per mirror when every value has its
field's exact type, and by the field-by-field plan otherwise (issue 22).  For every message type of
the interface folders, random samples are converted once on the compiled path and once with one
value of another type (a list as a tuple, a ``str`` subclass...), which only the general plan
takes: both give the same mirror, and the same sample on the way out.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

pytest.importorskip("cyclonedds")

from node_transport.dds_convert import DdsConverter  # noqa: E402
from node_transport.idl import InterfaceRegistry  # noqa: E402
from node_transport.mirrors import mirror  # noqa: E402
from node_transport.port import TransportError  # noqa: E402
from test_dds_cdr import samples  # noqa: E402

REGISTRY = InterfaceRegistry()
CONVERTER = DdsConverter(REGISTRY)
MESSAGE_TYPES = sorted(
    f"{path.parts[-3]}/msg/{path.stem}" for root in REGISTRY.roots for path in Path(root).glob("*/msg/*.msg")
)


class Text(str):
    pass


class Real(float):
    pass


class Whole(int):
    pass


def _off_path(value: Any, sequence: type) -> Any | None:
    """An equal value of a type the compiled path does not take, or None."""
    if type(value) in (list, tuple):
        return sequence(value)
    kind = {str: Text, float: Real, int: Whole}.get(type(value))
    return None if kind is None else kind(value)


def _perturbed(obj: Any, sequence: type) -> Any | None:
    """``obj`` with its first top-level value replaced by an equal one off the compiled path."""
    for field in dataclasses.fields(obj):
        other = _off_path(getattr(obj, field.name), sequence)
        if other is not None:
            return dataclasses.replace(obj, **{field.name: other})
    return None


@given(st.sampled_from(MESSAGE_TYPES).flatmap(lambda t: st.tuples(st.just(t), samples(REGISTRY.message(t)))))
def test_the_compiled_path_gives_the_general_answer(case: tuple[str, Any]) -> None:
    ros_type, sample = case
    cls = mirror(ros_type)
    try:
        msg = CONVERTER.from_wire(cls, sample)
    except TransportError:  # a value the mirror refuses (an octet the mirror holds as bytes...): refused both ways
        off = _perturbed(sample, tuple)
        if off is not None:
            with pytest.raises(TransportError):
                CONVERTER.from_wire(cls, off)
        return
    off = _perturbed(sample, tuple)
    if off is not None:
        assert CONVERTER.from_wire(cls, off) == msg
    wire = CONVERTER.to_wire(msg)
    assert CONVERTER.from_wire(cls, wire) == msg
    off_msg = _perturbed(msg, list)
    if off_msg is not None:
        assert CONVERTER.to_wire(off_msg) == wire


def test_a_value_of_the_wrong_kind_is_still_refused_naming_the_field() -> None:
    state = mirror("dual_arm_executive_interfaces/msg/MachineState")
    good = CONVERTER.to_wire(state(group="left_arm", state="Ready"))
    with pytest.raises(TransportError, match="group"):
        CONVERTER.to_wire(state(group=3, state="Ready"))  # type: ignore[arg-type]
    with pytest.raises(TransportError, match="group"):
        CONVERTER.from_wire(state, dataclasses.replace(good, group=b"\xff"))
