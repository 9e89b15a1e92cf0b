"""Paper Table 2, in one place: every state of the group machine and every signal out of it.

The machine is built from this table and nothing else, and the tests check it row by row, so
the running machine and the paper cannot disagree.  Table 1's working states come from
:class:`core_functions.primitives.WorkState`; Pause, Stop, ErrorHandling and Finish are the
states the paper leaves out of its figures.  Finish is final: the machine's outcome.

``Pause --resume--> (history)``: Table 2 writes "Cartesian/Articular motion" because that is its
example; with several working states, resume returns to whichever one was paused.
"""
from __future__ import annotations

from types import MappingProxyType

from core_functions.primitives import WorkState
from execution_engine.smach import HISTORY

READY = "Ready"
PAUSE = "Pause"
STOP = "Stop"
ERROR_HANDLING = "ErrorHandling"
FINISH = "Finish"

WORKING_STATES: tuple[str, ...] = tuple(w.value for w in WorkState)
SYNC_STATES: tuple[str, ...] = (WorkState.FULL_BODY_MOTION.value, WorkState.MASTER_SLAVE.value)
STATES: tuple[str, ...] = (READY, *WORKING_STATES, PAUSE, STOP, ERROR_HANDLING)

# Signals
OK = "ok"
PAUSE_SIGNAL = "pause"
STOP_SIGNAL = "stop"
ERROR = "error"
RESUME = "resume"
END = "end"

TABLE_2: MappingProxyType[str, MappingProxyType[str, str]] = MappingProxyType(
    {
        READY: MappingProxyType({**{w.request_signal: w.value for w in WorkState}, END: FINISH}),
        **{
            state: MappingProxyType({OK: READY, PAUSE_SIGNAL: PAUSE, STOP_SIGNAL: STOP, ERROR: ERROR_HANDLING})
            for state in WORKING_STATES
        },
        PAUSE: MappingProxyType({RESUME: HISTORY, STOP_SIGNAL: STOP, ERROR: ERROR_HANDLING}),
        STOP: MappingProxyType({ERROR: ERROR_HANDLING}),
        ERROR_HANDLING: MappingProxyType({OK: READY, END: FINISH}),
    }
)


def signals_of(state: str) -> tuple[str, ...]:
    """The outcomes (signals) a state may emit: exactly its row of Table 2."""
    return tuple(TABLE_2[state])
