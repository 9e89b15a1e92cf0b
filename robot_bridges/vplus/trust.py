"""What the V+ back end believes of a controller's acks: a pose is checked against where the arm was sent.

AdeptServer acknowledges a skill when its V+ program returns, and every ack carries the pose of
the arm at that moment.  Nothing in the protocol says the arm went where it was told: a controller
(or something posing as one) can acknowledge every move and report any pose.  So, as the KUKA RSI
side does with its set point (``robot_bridges/kuka_rsi/guard.py``), the back end checks each
reported pose against the one it commanded -- the end of a motion against its goal, the start of
a motion and the ack of a hand action against where the last motion ended -- within a tolerance
(``tolerance_mm``, ``tolerance_deg``).  A disagreement is a fault (``controller``), never an input,
and the back end trusts that controller no more: every later primitive fails with the same words
until a new run connects again.

The one pose taken without a check is the answer to a lone ``break`` after a connection or a
failure: the arm may have finished a motion whose ack was lost, so that answer *is* where it is.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core_functions.option_ranges import Range, bounds
from robot_bridges.vplus.kinematics import location_to_matrix, matrix_to_location

Matrix = NDArray[np.float64]

#: Defaults: a V+ MOVE ends within a few hundredths of a millimetre of its location; a millimetre
#: and half a degree leave room for a controller's calibrated kinematics against the nominal
#: model of a joint move, and catch any arm that did not go where it was sent.
TOLERANCE_MM = 1.0
TOLERANCE_DEG = 0.5
#: An ack pose this close to the one predicted confirms the commanded joints (else IK explains it).
AGREE_MM, AGREE_DEG = 0.5, 0.05
#: option -> default; each one's range, in core_functions.option_ranges (V+'s own tolerance_mm), is
#: finite and never so wide that a report could stray a hand's width from the command unnoticed.
_DEFAULTS = {"tolerance_mm": TOLERANCE_MM, "tolerance_deg": TOLERANCE_DEG}


def _range(name: str) -> Range:
    return bounds(name, "vplus")


def _refusal(name: str, got: str) -> str:
    return f"{name} must be a number in {_range(name).describe()}, got {got}"


@dataclass(frozen=True)
class PoseTolerance:
    """How far a reported pose may lie from the commanded one: millimetres and degrees."""

    mm: float = TOLERANCE_MM
    deg: float = TOLERANCE_DEG

    def __post_init__(self) -> None:
        for name, value in (("tolerance_mm", self.mm), ("tolerance_deg", self.deg)):
            if not _range(name).contains(value):
                raise ValueError(_refusal(name, f"{value:g}"))

    @classmethod
    def from_options(cls, extra: Mapping[str, str], label: str) -> PoseTolerance:
        """The ``tolerance_mm`` / ``tolerance_deg`` back-end options; a ValueError naming the option otherwise."""
        values = []
        for name, default in _DEFAULTS.items():
            text = extra.get(name)
            try:
                values.append(default if text is None else float(text))
            except ValueError:
                raise ValueError(f"{label}: {_refusal(name, repr(text))}") from None
        try:
            return cls(*values)
        except ValueError as error:
            raise ValueError(f"{label}: {error}") from None

    def __str__(self) -> str:
        return f"{self.mm:g} mm, {self.deg:g} deg"


def apart(a: Matrix, b: Matrix) -> tuple[float, float]:
    """How far two poses are apart: millimetres between the origins, degrees between the orientations."""
    shift = float(np.linalg.norm(a[:3, 3] - b[:3, 3])) * 1000.0
    cos = (float(np.trace(a[:3, :3].T @ b[:3, :3])) - 1.0) / 2.0
    return shift, math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def agree(a: Matrix, b: Matrix) -> bool:
    """Close enough that the commanded joints explain the reported pose."""
    shift, turn = apart(a, b)
    return shift <= AGREE_MM and turn <= AGREE_DEG


def disagreement(label: str, what: str, commanded: Matrix, reported: Sequence[float], tolerance: PoseTolerance) -> str | None:
    """None when ``reported`` (a V+ location) lies within ``tolerance`` of ``commanded``; else the one line saying so."""
    shift, turn = apart(commanded, location_to_matrix(reported))
    if shift <= tolerance.mm and turn <= tolerance.deg:
        return None
    return (
        f"{label}: {what}: commanded {_location(matrix_to_location(commanded))}, the controller reports {_location(reported)} "
        f"({shift:.3f} mm and {turn:.3f} deg apart; tolerance {tolerance}): the controller did not move where it was told"
    )


def _location(loc: Sequence[float]) -> str:
    """x,y,z mm and yaw,pitch,roll deg as on the wire (three decimals)."""
    return ",".join(f"{v:.3f}" for v in loc) + " (mm, deg)"
