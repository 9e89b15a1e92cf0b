"""The application's signals on a KUKA over RSI: ``set_output`` and ``wait_input`` by the names the configuration gives.

Whatever the RSI configuration carries besides motion is the application's: kroshu's ``GPIO.01`` (an output
in ``<Sen>``, read back in ``<Rob>``) and ``GPIO.02`` (an input), the technology parameters ``Tech.C11`` ..
(inputs) and ``Tech.T21`` .. (outputs), any element a context wires to an ETHERNET channel.  Outputs the
bridge drives itself -- the corrections, ``Stop``, the handshake flags, the tool outputs (``end_effector``)
-- and an external axis's correction (kroshu's ``EK.E1``), which no limiter would hold, are not the
application's to set.  A BOOL travels as a flag bit, anything else through the loop's
control messages (:mod:`.io_values`); every wait is bounded in robot cycles, as the rest of the back end's.
"""
from __future__ import annotations

import math

from core_functions.primitives import IoResult, SetOutput, WaitInput
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.kuka_rsi.arm_commands import Run
from robot_bridges.kuka_rsi.config import Field, RsiConfig, RsiRoles
from robot_bridges.kuka_rsi.io_values import FEEDBACK_ELEMENTS, convert
from robot_bridges.kuka_rsi.loop_events import LoopEvents


class Signals:
    """One robot's application signals: which there are, setting one, waiting for one."""

    def __init__(self, events: LoopEvents, config: RsiConfig, roles: RsiRoles, cycle_s: float) -> None:
        self.events = events
        self.config = config
        self.cycle_s = cycle_s
        driven = {
            *roles.axis_correction, *roles.cart_correction, roles.stop, roles.allow_start, roles.allow_move, roles.allow_finish,
            roles.request_end, *roles.tools(config),
        }
        # Corrections move axes: never a signal, whether the bridge drives them (AK, RKorr) or not (kroshu's EK.E1,
        # an external axis the bridge does not drive and no limiter would hold).
        motion = {field.split(".", 1)[0] for field in (*roles.axis_correction, *roles.cart_correction)} | {"EK"}
        self.outputs: dict[str, Field] = {f.key: f for f in config.receive_fields if f.key not in driven and f.element not in motion}
        self.inputs: dict[str, Field] = {f.key: f for f in config.send_fields if f.element not in FEEDBACK_ELEMENTS}

    def _unknown(self, kind: str, name: str, known: dict[str, Field]) -> BridgeError:
        names = ", ".join(known) or "none"
        return BridgeError(FaultKind.UNSUPPORTED, f"{self.events.name}: {self.config.source} has no {kind} {name!r} (its {kind}s: {names})")

    async def set_output(self, primitive: SetOutput) -> IoResult:
        """Put the value in the replies; done once a reply carries it."""
        field = self.outputs.get(primitive.name)
        if field is None:
            raise self._unknown("output", primitive.name, self.outputs)
        events, iface = self.events, self.events.iface
        assert iface is not None
        name = self.events.name
        if field.type == "BOOL":
            if primitive.value not in (0.0, 1.0):
                raise BridgeError(FaultKind.UNSUPPORTED, f"{name}: {field.key} is a BOOL: 0 or 1, not {primitive.value:g}")
            value = primitive.value == 1.0
            iface.set_flag(0, field.key, value)
            await events.until(lambda: iface.flag_sent(0, field.key) == value, events.handshake_cycles, f"a reply carrying {field.key}")
            return IoResult({field.key: float(value)})
        try:
            convert(field, primitive.value)
        except ValueError as error:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{name}: {error}") from None
        iface.set_output(0, field.key, primitive.value)
        sent = iface.events.outputs[0]
        await events.until(lambda: field.key in sent, events.handshake_cycles, f"a reply carrying {field.key}")
        value, problem = sent[field.key]
        if problem:
            raise BridgeError(FaultKind.UNSUPPORTED, f"{name}: {problem}")
        return IoResult({field.key: float(value)})

    def read(self, field: Field) -> float | None:
        """The input's latest value (None: not read yet)."""
        iface = self.events.iface
        assert iface is not None
        if field.type == "BOOL":
            return float(iface.digout(0, field.key))
        value = iface.events.inputs[0].get(field.key)
        return None if value is None else float(value)

    async def wait_input(self, primitive: WaitInput, run: Run) -> IoResult:
        """Until the input reads the value (within the tolerance); a timeout after ``timeout`` s of robot time."""
        field = self.inputs.get(primitive.name)
        if field is None:
            raise self._unknown("input", primitive.name, self.inputs)
        name = self.events.name
        if field.type == "STRING":
            raise BridgeError(FaultKind.UNSUPPORTED, f"{name}: {field.key} is a STRING; wait_input compares numbers")
        cycles = math.ceil(primitive.timeout / self.cycle_s - 1e-9)

        def there() -> bool:
            value = self.read(field)
            return value is not None and abs(value - primitive.value) <= primitive.tolerance

        try:
            await self.events.until(lambda: there() or run.stopped, cycles, f"{field.key} = {primitive.value:g}")
        except BridgeError as error:
            if error.kind is not FaultKind.TIMEOUT or self.events.fault is not None:
                raise
            now = self.read(field)
            reads = "nothing yet" if now is None else f"{now:g}"
            raise BridgeError(
                FaultKind.TIMEOUT, f"{name}: input {field.key} did not read {primitive.value:g} within {primitive.timeout:g} s of robot time (it reads {reads})"
            ) from None
        if run.stopped:
            raise BridgeError(FaultKind.STOPPED, f"{name}: stopped")
        value = self.read(field)
        return IoResult({field.key: value if value is not None else math.nan})
