"""The application's signals in the loop: numeric values of the RSI configuration, read and written by name.

A configuration carries more than motion: kroshu's GPIO elements (``GPIO.01``), the technology parameters
of ``DEF_Tech`` (``Tech.C11`` .. ``Tech.T210``), any element a context wires to an ETHERNET channel.  Their
BOOLs already travel as bits (the flags the external system sends, the digital outputs it reads); this
module is the rest -- LONG, DOUBLE and STRING values: an output is set in the reply by a control message,
an input that changed is reported after the reply, never more than once a cycle.
"""
from __future__ import annotations

from collections.abc import Sequence

from robot_bridges.kuka_rsi.codec import Value
from robot_bridges.kuka_rsi.config import Field

#: Elements the external system reads as motion feedback, not as the application's signals.
FEEDBACK_ELEMENTS = frozenset({"RIst", "RSol", "AIPos", "ASPos", "EIPos", "ESPos", "MACur", "MECur", "Delay"})


def input_keys(fields: Sequence[Field]) -> tuple[str, ...]:
    """The numeric values of ``<Rob>`` the application may wait for (BOOLs travel as bits)."""
    return tuple(f.key for f in fields if f.type != "BOOL" and f.element not in FEEDBACK_ELEMENTS)


def output_keys(fields: Sequence[Field], driven: Sequence[str]) -> tuple[str, ...]:
    """The numeric values of ``<Sen>`` the application may set: all but the ones the bridge drives itself."""
    taken = set(driven)
    return tuple(f.key for f in fields if f.type != "BOOL" and f.key not in taken)


def convert(field: Field, value: object) -> Value:
    """``value`` as the field's type carries it; ValueError when it cannot be."""
    if field.type == "LONG":
        number = float(value)  # type: ignore[arg-type]
        if not number.is_integer() or abs(number) >= 2**63:
            raise ValueError(f"{field.key} is a LONG: {value!r} is not a whole number")
        return int(number)
    if field.type == "DOUBLE":
        number = float(value)  # type: ignore[arg-type]
        if number != number or number in (float("inf"), float("-inf")):
            raise ValueError(f"{field.key} is a DOUBLE: {value!r} is not a finite number")
        return number
    if field.type == "STRING":
        return str(value)
    return bool(value)


class IoValues:
    """One robot's numeric signals: which packet slots, and what was last reported of the inputs."""

    def __init__(self, rob_fields: Sequence[Field], sen_fields: Sequence[Field], driven: Sequence[str]) -> None:
        self._rob = {f.key: i for i, f in enumerate(rob_fields)}
        self._sen = {f.key: (i, f) for i, f in enumerate(sen_fields)}
        self.inputs = input_keys(rob_fields)
        self.outputs = output_keys(sen_fields, driven)
        self._input_slots = [self._rob[k] for k in self.inputs]
        self._last: tuple[Value, ...] | None = None

    def set(self, tx: list[Value], key: str, value: object) -> str | None:
        """Put an output into the reply values; why not, when it cannot be."""
        if key not in self.outputs:
            return f"{key} is not a numeric value the configuration sends to the robot"
        index, field = self._sen[key]
        try:
            tx[index] = convert(field, value)
        except (TypeError, ValueError) as error:
            return str(error)
        return None

    def changed(self, rx: Sequence[Value]) -> dict[str, Value] | None:
        """The inputs of this packet when any differs from the last packet's (all of them), else None."""
        if not self._input_slots:
            return None
        now = tuple(rx[i] for i in self._input_slots)
        if now == self._last:
            return None
        self._last = now
        return dict(zip(self.inputs, now))
