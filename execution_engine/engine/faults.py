"""Which faults a retry can cure: the one table the engine's error policy reads.

A retry sends the same function with the same parameters to the same robot again.  It can only
succeed when the fault came from something that changes by itself between two tries: a late
answer, a broken link that reconnects, a camera that saw glare.  A target out of reach, a joint
limit or a collision come back identically on the second try -- retrying them costs cycle time,
and a collision repeated is a second crash -- so they go straight to the policy's final action
(abort, safe pose, or an alarm, where an operator who has fixed the cause may retry).
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from node_transport.wire import FaultKind


@dataclass(frozen=True)
class Retry:
    """Whether a fault kind is worth a second try, and the reason an operator reads."""

    retryable: bool
    why: str


DETERMINISTIC = "is deterministic"

#: Every kind a bridge or a machine reports; a test keeps it complete.
RETRY_TABLE: dict[FaultKind, Retry] = {
    FaultKind.TIMEOUT: Retry(True, "is transient (a controller, bridge or partner answered late)"),
    FaultKind.CONNECTION: Retry(True, "is transient (the link can come back)"),
    FaultKind.VISION: Retry(True, "can succeed on a second look (lighting, glare, a part settling)"),
    FaultKind.BUSY: Retry(True, "is transient (the earlier primitive is stopped by the reset)"),
    FaultKind.UNREACHABLE: Retry(False, DETERMINISTIC),
    FaultKind.JOINT_LIMIT: Retry(False, DETERMINISTIC),
    FaultKind.COLLISION: Retry(False, f"{DETERMINISTIC} (and needs an operator to look at the cell)"),
    FaultKind.UNSUPPORTED: Retry(False, DETERMINISTIC),
    FaultKind.SKILL: Retry(False, f"{DETERMINISTIC} (the skill's own code raised)"),
    FaultKind.OUT_OF_RANGE: Retry(False, "is what the part measures: a second look measures the same"),
    FaultKind.PROTOCOL: Retry(False, "is a mismatch with the controller or bridge, not a passing fault"),
    FaultKind.CONTROLLER: Retry(False, "must be cleared on the controller by an operator"),
    FaultKind.STOPPED: Retry(False, "was a stop: stops are obeyed, not retried"),
    FaultKind.INTERNAL: Retry(False, "is a defect in the bridge or the machine"),
}

_UNKNOWN = Retry(False, "was not reported, and an unknown fault is not retried")  # an old bridge, say


def verdict(faults: Iterable[FaultKind | None]) -> tuple[bool, str]:
    """Retry only when every failed group's fault is retryable; else the first reason why not.

    The reason reads after "not retried: ", e.g. "joint_limit is deterministic".
    """
    kinds = list(faults)
    known = [kind for kind in kinds if kind is not None]
    if not known or len(known) != len(kinds):
        return False, f"the fault kind {_UNKNOWN.why}"
    for kind in known:
        if not RETRY_TABLE[kind].retryable:
            return False, f"{kind.value} {RETRY_TABLE[kind].why}"
    return True, f"{known[0].value} {RETRY_TABLE[known[0]].why}"
