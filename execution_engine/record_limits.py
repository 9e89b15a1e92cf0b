"""How much a run's record -- a JSON-lines trace or an MCAP recording -- may ask of the program that reads it.

``report`` and ``--resume`` read files from outside: a file from another computer, cut by a crash,
or crafted.  Its size bounds the reading only if nothing in it can make the reader do more than a
run's record ever needs: a recording's compressed chunks are capped in what they may unpack
(:mod:`execution_engine.recorder.safe_read`), and here are the bounds on what any record says.

* Groups: a robot has a few (the Nextage three, the engine a lane of its own); a record naming more
  than :data:`MAX_GROUPS` is refused, since each is a lane of the report and of the timeline.
* Times: a run's time is finite and within :data:`TIME_BOUND` seconds (116 days) of its start;
  a record at ``1e308`` or ``NaN`` s is no event of a run, and is refused where it stands.
* Nesting: a record is a few levels deep (a primitive's result inside it at most the wire's 64);
  one nested deeper than :data:`MAX_NESTING` levels is refused where it stands, before anything
  walks it (a line of a megabyte of ``[`` made the JSON parser itself give up).

A refusal is :class:`OverLimit`: one line naming the file and the limit.
"""
from __future__ import annotations

import math

from core_functions.printable import printable

#: Groups (lanes) a record may name, the engine's included.
MAX_GROUPS = 64
#: Seconds of run time either side of the run's start (116 days).
TIME_BOUND = 1e7
#: Levels of lists and objects a record may nest (the wire admits 64 inside one field).
MAX_NESTING = 100


class OverLimit(ValueError):
    """A record asks more than a run's record can: the message names the file and the limit."""


def time_problem(t: object) -> str | None:
    """Why ``t`` is no time of a run (not a number, not finite, past the bound), or None."""
    if isinstance(t, bool) or not isinstance(t, (int, float)):
        return f"t = {str(t)[:40]!r} is not a number of seconds"
    if not math.isfinite(t) or abs(t) > TIME_BOUND:
        return f"t = {t:g} s is not a time of a run (finite, within ±{TIME_BOUND:.0f} s of its start)"
    return None


def nesting_problem(value: object) -> str | None:
    """Why ``value`` nests too deep to be a record (walked without recursion), or None."""
    pending: list[tuple[object, int]] = [(value, 1)]
    while pending:
        item, level = pending.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        if level > MAX_NESTING:
            return f"nested more than {MAX_NESTING} levels deep: no record of a run is"
        pending.extend((child, level + 1) for child in children)
    return None


class GroupCount:
    """The groups a record has named so far; OverLimit at the first past :data:`MAX_GROUPS`."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.seen: set[str] = set()

    def see(self, group: str, where: str = "") -> None:
        if group in self.seen:
            return
        if len(self.seen) >= MAX_GROUPS:
            at = f" ({where})" if where else ""
            raise OverLimit(f"{printable(self.path)}: refused: more than {MAX_GROUPS} groups{at}, the {MAX_GROUPS + 1}th '{printable(group[:40])}'; "
                            "a robot's run has a few, each a lane of the report: a damaged or crafted file")
        self.seen.add(group)
