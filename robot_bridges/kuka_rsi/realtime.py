"""Real-time scheduling on the RSI side: who asks for it, and what a run without it means.

A KR C4's RSI is hard real time, and so must its partners be: the loop asks for ``SCHED_FIFO`` 10
in its own process (:mod:`.external`), and the simulated controller the back end starts asks for
:data:`SIMULATOR_PRIORITY`, above it, since the controller's clock comes first.  Where the system
grants neither (an ordinary user without ``rtprio``), both are processes like any other: a busy
computer makes the loop late and holds the simulator back, which docs/kuka_rsi.md ("On a busy
computer") measures.
"""
from __future__ import annotations

import os

#: ``SCHED_FIFO`` priority of a simulated controller's process (the loop's is 10).
SIMULATOR_PRIORITY = 20

#: Seconds without packets from a simulated real-time controller that mean it is lost.  A real
#: controller is hard real time and 0.1 s of silence means a cable or a stopped RSI; the simulator is
#: a process of this computer, which a busy computer held back 101-115 ms when the system granted it
#: no real-time priority (beside two or three CPU-bound processes on two cores).  Its real stops (RSI
#: timeout, limits) it reports itself, and its exit is seen at once.
SIMULATED_SILENCE = 1.0


def ask_realtime(priority: int) -> str:
    """``SCHED_FIFO`` at ``priority`` for this process (0: none asked); what took effect, in words."""
    if priority <= 0:
        return "no real-time priority asked"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError) as error:
        return f"no real-time priority ({error.strerror or error})"
    return f"SCHED_FIFO {priority}"


def realtime_advice(tuning: str) -> str | None:
    """What to do when the RSI loop runs without real-time priority (from its tuning note); None when it has it."""
    if "no real-time priority" not in tuning:
        return None
    return (
        f"the RSI loop runs without real-time priority ({tuning.split('no real-time priority', 1)[1].strip(' ()') or 'refused'}): "
        "on a busy computer its replies will be late (each one counted by the controller, which stops RSI after its "
        "timeout of late replies in a row); allow this user real-time scheduling (e.g. 'USER - rtprio 20' in "
        "/etc/security/limits.conf, or CAP_SYS_NICE) -- docs/kuka_rsi.md, 'On a busy computer'"
    )
