"""'Did you mean ...?' for a name among many, at a bounded cost per question.

``difflib.get_close_matches`` compares the name with every candidate: fine for the sixty
functions of the catalog, but a cell of 200,000 frames made each unknown frame name cost a
second, and an application with many of them ran for minutes.  :class:`NameIndex` keeps small
sets exact (every candidate is compared, as difflib does) and, for large ones, compares only the
names next to the unknown one in two sorted orders -- by their beginning and by their end --
which is where a typo lands: a letter added, dropped or swapped keeps one end of the name intact.
Building the index is one sort; each question then costs a binary search and at most
``2 * 2 * WINDOW`` comparisons, whatever the size of the set.
"""
from __future__ import annotations

import bisect
import difflib
from collections.abc import Iterable

#: Up to this many names every one is compared (the exact difflib answer).
EXACT_UP_TO = 2000
#: For larger sets: the neighbours compared on each side, in each of the two orders.
WINDOW = 48


class NameIndex:
    """The names of a set, sorted by their beginning and by their end, built on first use."""

    def __init__(self, names: Iterable[str]) -> None:
        self._source = names
        self._names: list[str] | None = None
        self._forward: list[str] = []
        self._backward: list[str] = []  # each name reversed, sorted

    def _build(self) -> list[str]:
        if self._names is None:
            self._names = list(self._source)
            if len(self._names) > EXACT_UP_TO:
                self._forward = sorted(self._names)
                self._backward = sorted(name[::-1] for name in self._names)
        return self._names

    def candidates(self, name: str) -> list[str]:
        """The names compared with ``name``: all of a small set, the neighbours in a large one."""
        names = self._build()
        if len(names) <= EXACT_UP_TO:
            return names
        picked: dict[str, None] = {}
        for ordered, key, flip in ((self._forward, name, False), (self._backward, name[::-1], True)):
            at = bisect.bisect_left(ordered, key)
            for neighbour in ordered[max(0, at - WINDOW):at + WINDOW]:
                picked[neighbour[::-1] if flip else neighbour] = None
        return list(picked)

    def suggest(self, name: str) -> str | None:
        """The closest name, or None when nothing is close enough (difflib's 0.6 ratio)."""
        close = difflib.get_close_matches(name, self.candidates(name), n=1)
        return close[0] if close else None


def did_you_mean(close: str | None) -> str:
    """The hint appended to an 'unknown name' message."""
    return f" (did you mean {close!r}?)" if close else ""
