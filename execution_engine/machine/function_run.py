"""One function request being executed: the skill's generator and where it has got to.

The machine pulls primitives out of the skill one at a time and pushes each result back in, so
the skill decides its next primitive knowing what the last one measured.  Errors raised by the
skill's own code (a frame it cannot find, a rivet that does not fit) surface here, as the
function's error, not as a crash of the machine.
"""
from __future__ import annotations

from typing import Any

from core_functions.catalog import FunctionSpec
from core_functions.functions import OutOfRange, Skill
from core_functions.primitives import Primitive
from node_transport.wire import FaultKind, SmRequest


class SkillError(RuntimeError):
    """The skill's own code failed; the message names the function.  ``fault``: SKILL, or OUT_OF_RANGE
    for a measured value outside the range the function checks (an outcome an ``<if>`` may test)."""

    def __init__(self, message: str, fault: FaultKind = FaultKind.SKILL) -> None:
        super().__init__(message)
        self.fault = fault


class FunctionRun:
    """The state of one function of one operation on one group."""

    def __init__(self, request: SmRequest, spec: FunctionSpec, skill: Skill, t_start: float) -> None:
        self.request = request
        self.spec = spec
        self._skill = skill
        self.t_start = t_start
        self.next_primitive: Primitive | None = None
        self.started = 0  # primitives handed to a working state
        self.finished = False

    @property
    def label(self) -> str:
        return f"{self.request.function} (operation {self.request.operation})"

    def start(self) -> None:
        """Compute the first primitive (a skill may finish without any, like ``wait``)."""
        self._step(lambda: next(self._skill))

    def advance(self, result: Any) -> None:
        """Give the current primitive's result to the skill and compute the next primitive."""
        self._step(lambda: self._skill.send(result))

    def take(self) -> Primitive:
        """Hand the next primitive to a working state."""
        if self.next_primitive is None:
            raise RuntimeError(f"{self.label} has no primitive pending")
        primitive, self.next_primitive = self.next_primitive, None
        self.started += 1
        return primitive

    def close(self) -> None:
        """Abandon the skill (stop, error, end); its ``finally`` blocks run."""
        self._skill.close()
        self.next_primitive = None

    def _step(self, advance: Any) -> None:
        try:
            self.next_primitive = advance()
        except StopIteration:
            self.next_primitive = None
            self.finished = True
        except OutOfRange as error:  # what the part measures: a named outcome where an <if> tests it
            self.next_primitive = None
            raise SkillError(f"{self.label}: {error}", FaultKind.OUT_OF_RANGE) from error
        except Exception as error:  # noqa: BLE001 - the skill's fault becomes the function's error
            self.next_primitive = None
            raise SkillError(f"{self.label}: {type(error).__name__}: {error}") from error
