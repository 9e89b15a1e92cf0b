"""What the controller holds of our corrections: RSI's own rules applied to the replies we sent.

The external system must not plan from what the controller *reports* (``ASPos``, ``RSol``): a
peer can report a set point that has nothing to do with what it was told (ROS-Industrial's
``kuka_rsi_simulator`` keeps ``ASPos`` at its start pose), and planning from it commands a jump.
But the external system knows what it sent, and RSI's rules say what the controller made of it:

* a reply that arrived in time is applied in its cycle;
* a cycle without one (our reply was late, withheld, or the packet was never answered) counts in
  ``Delay`` and each RECEIVE value keeps its last value (HOLDON=1) or falls to zero (HOLDON=0);
* an *absolute* correction is the value in force; a *relative* one is added to the total.

:class:`CycleAccount` reads, from each packet's ``Delay`` and IPOC, whether our previous reply was
applied and how many cycles passed without one; :class:`CorrectionModel` plays those cycles
forward from our own replies.  The result -- the set point the controller holds if it does what
RSI says -- is what every motion is planned from, and what the controller's report is checked
against (:mod:`.guard`).
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.kinematics import abc_to_matrix, matrix_to_abc

Vector = NDArray[np.float64]
_DEG = np.pi / 180.0


class CycleAccount:
    """Per packet: was our reply to the previous packet applied, and how many cycles held.

    Between two packets we answered, ``c`` controller cycles closed: the previous packet's (on
    time if our reply made it) and ``c - 1`` whose packets we never answered (skipped as stale,
    lost on the way).  ``Delay`` grew by ``n``; so our reply was late iff ``n - (c - 1) >= 1``.
    ``c`` comes from the IPOC difference over the IPOC step: a KR C4 counts milliseconds (4 or 12 a
    cycle), ROS-Industrial's simulator counts packets (1), and repeats an IPOC after a timeout (0
    cycles).  Unless configured, the step is learned as the smallest IPOC difference of two
    packets without a late reply between them.  Without ``Delay`` the IPOC alone says it.
    """

    def __init__(self, ipoc_step: int | None, guess: int) -> None:
        self._fixed = ipoc_step
        self.step = ipoc_step or guess
        self._ipoc: int | None = None
        self._delay = 0

    def reset(self, ipoc: int, delay: int | None) -> None:
        """Start counting at this packet (nothing of ours is in flight)."""
        self._ipoc = ipoc
        self._delay = delay or 0

    def account(self, ipoc: int, delay: int | None) -> tuple[bool, int]:
        """``(our reply to the previous packet was applied, cycles that held without a reply)``."""
        if self._ipoc is None:
            self.reset(ipoc, delay)
            return False, 0
        diff = ipoc - self._ipoc
        self._ipoc = ipoc
        cycles = round(diff / self.step) if diff > 0 else 0
        if delay is None:
            return True, max(0, cycles - 1)
        late = max(0, delay - self._delay)
        self._delay = delay
        if late == 0:
            if diff > 0 and self._fixed is None and diff < self.step:
                self.step = diff
            return True, 0
        return late - (cycles - 1) <= 0, late


class CorrectionModel:
    """The correction in force on the controller (protocol units), cycle by cycle.

    ``holdon`` per value, from the RSI configuration.  ``compose`` adds an increment to a total in
    relative mode (Cartesian rotations compose; by default values add).  :attr:`history` keeps the
    last totals, newest last, for the step of the last cycle and for a report one cycle old.
    """

    def __init__(self, holdon: Sequence[bool], relative: bool, depth: int = 3, compose: Callable[[Vector, Vector], Vector] | None = None) -> None:
        self.keep = np.array(holdon, dtype=bool)
        self.relative = relative
        self._compose = compose or np.add
        self._depth = max(2, depth)
        self.reset()

    def reset(self) -> None:
        size = len(self.keep)
        self.held = np.zeros(size)  # what RSI holds as the last received values
        self.total = np.zeros(size)  # the correction in force
        self.history: deque[Vector] = deque([self.total] * self._depth, maxlen=self._depth)

    def cycle(self, reply: Vector | None) -> None:
        """One controller cycle: our reply arrived in time with these values, or (None) not."""
        value = reply if reply is not None else np.where(self.keep, self.held, 0.0)
        self.held = value
        self.total = self._compose(self.total, value) if self.relative else value
        self.history.append(self.total)

    def start_from(self, total: Vector) -> None:
        """The controller already holds ``total`` when the account begins (a correction from before);
        absolute: its last received values were that total, relative: the increment repeated is unknown, none."""
        self.total = np.array(total, dtype=float)
        self.held = self.total.copy() if not self.relative else np.zeros(len(self.keep))
        self.history = deque([self.total] * self._depth, maxlen=self._depth)

    @property
    def previous(self) -> Vector:
        """The total one cycle before the current one."""
        return self.history[-2]

    def reply_for(self, desired: Vector, difference: Callable[[Vector, Vector], Vector] | None = None) -> Vector:
        """The values that bring the total to ``desired``: itself (absolute) or the increment (relative)."""
        if not self.relative:
            return desired
        return difference(desired, self.total) if difference is not None else desired - self.total


def compose_cartesian(total: Vector, increment: Vector) -> Vector:
    """A relative ``RKorr`` increment (mm, deg) on a total: translations add, rotations compose."""
    rotation = abc_to_matrix(*(increment[3:] * _DEG)) @ abc_to_matrix(*(total[3:] * _DEG))
    return np.concatenate((total[:3] + increment[:3], np.array(matrix_to_abc(rotation)) / _DEG))


def cartesian_increment(desired: Vector, total: Vector) -> Vector:
    """The ``RKorr`` increment that :func:`compose_cartesian` turns ``total`` into ``desired`` with."""
    rotation = abc_to_matrix(*(desired[3:] * _DEG)) @ abc_to_matrix(*(total[3:] * _DEG)).T
    return np.concatenate((desired[:3] - total[:3], np.array(matrix_to_abc(rotation)) / _DEG))
