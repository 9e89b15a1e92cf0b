"""Physical bounds: what a robot cell can have, in one table for every reader of outside numbers.

A value can be a perfectly good float and still mean nothing in a cell: a frame 1e308 m away, a
roll of 1e308 rad, a wait of a century.  Such values pass every type check and fail much later --
an overflow in the pose maths, an angle that wraps to something meaningless, an 'internal' error
in a bridge.  So every reader of numbers that came from a user -- the cell and application
readers, the catalog's param parsing, the bridges where they check their inputs -- takes its
bounds from here, and ``validate`` refuses exactly what a run could not do.

The bounds are deliberately generous (a cell is not 100 m across, an angle param need not be two
turns); the catalog and the robot add the tighter, meaningful limits (joint limits, a function's
own minimum and maximum).  docs/application_xml.md shows this table to users.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Bound:
    """The closed interval a quantity may take, in its SI unit, and what it bounds (for messages)."""

    lower: float
    upper: float
    unit: str
    what: str

    def contains(self, value: float) -> bool:
        return math.isfinite(value) and self.lower <= value <= self.upper

    def describe(self, factor: float = 1.0, unit: str | None = None) -> str:
        """The interval in a unit of ``factor`` SI units each (``±100000 mm``, ``[0, 86400] s``)."""
        shown = unit if unit is not None else self.unit
        lower, upper = self.lower / factor, self.upper / factor
        if lower == -upper:
            return f"±{upper:g} {shown}".rstrip()
        return f"[{lower:g}, {upper:g}] {shown}".rstrip()

    def violation(self, field: str, written: float, factor: float = 1.0, unit: str | None = None) -> str | None:
        """Why ``written`` (in a unit of ``factor`` SI units) is out of bounds, or None when it is in.

        The message names the field, the value and the bound in the unit the user wrote, so it
        can be fixed where it stands.
        """
        value = written * factor
        if self.contains(value):
            return None
        shown = unit if unit is not None else self.unit
        return f"{field} = {written:g} {shown} is outside {self.describe(factor, shown)}, {self.what}".replace("  ", " ")


#: A position or offset in a cell: a frame's xyz (local and in the world), an inline target, a
#: length param.  No robot of this project reaches 3 m; 100 m leaves room for any layout.
LENGTH = Bound(-100.0, 100.0, "m", "the bound of a length in a cell")
#: An orientation angle (roll, pitch, yaw of a frame or an inline target) or an angle param:
#: two turns either way.  Beyond that a value is a typo or a unit mix-up, never a pose.
ANGLE = Bound(-4.0 * math.pi, 4.0 * math.pi, "rad", "the bound of an angle (two turns)")
#: A linear speed of the tool.
SPEED = Bound(0.0, 10.0, "m/s", "the bound of a tool speed")
#: A fraction (of full speed, of a range): 0 to 1, i.e. 0 % to 100 %.
FRACTION = Bound(0.0, 1.0, "", "the bound of a fraction (0 to 1, i.e. 0 % to 100 %)")
#: A duration: a wait, a timeout, a trajectory's length.  One day.
DURATION = Bound(0.0, 86_400.0, "s", "the bound of a duration (one day)")

#: Bounds by unit (the catalog's unit families, core_functions.catalog): every number param is
#: checked against its family's bound as well as its own minimum and maximum, and the readers
#: look their bounds up here too, so one change of this table changes every check.
BY_UNIT: dict[str, Bound] = {"m": LENGTH, "rad": ANGLE, "m/s": SPEED, "fraction": FRACTION, "s": DURATION}

#: How often the engine retries a failed function (error_policy retries; the XSD's ``count``
#: type carries the same number, checked by a test).
MAX_RETRIES = 1000


def table() -> list[tuple[str, str, str]]:
    """(quantity, bound, where it applies), for the docs and ``functions`` listings."""
    return [
        ("length", LENGTH.describe(), "cell frame xyz (local and world), <actual> xyz, inline target x y z, length params"),
        ("angle", f"{ANGLE.describe()} ({ANGLE.describe(math.pi / 180.0, 'deg')})", "cell frame rpy, <actual> rpy, inline target roll pitch yaw, angle params"),
        ("speed", SPEED.describe(), "speed params"),
        ("fraction", FRACTION.describe(), "fraction params (50% = 0.5)"),
        ("duration", DURATION.describe(), "time params, error_policy alarm_timeout"),
        ("retries", f"[0, {MAX_RETRIES}]", "error_policy retries"),
    ]
