"""Tool paths streamed one point per RSI cycle: ITRA's computer-based approach (``setToolPathFromFile``).

The trajectory is planned beforehand and every interpolation cycle takes the next point, so the
path is followed exactly -- but nothing smooths it any more: a point too far from the previous
one is a jump the robot must not make.  So a file is checked completely before a single point
is sent: every value finite, joints inside their limits, and no step between two consecutive
points (or from the robot to the first point) faster than the limits allow.  Problems are
reported with the file and line.

File format (text, one point per line, ``#`` starts a comment, values separated by blanks or
commas), in the controller's units because such files come from KUKA tooling:

* ``joint``: ``A1 A2 A3 A4 A5 A6`` in degrees;
* ``cartesian``: ``X Y Z`` in mm and ``A B C`` in degrees (KUKA's Z-Y'-X'' angles).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.kinematics import abc_to_matrix, rotation_angle

Space = Literal["joint", "cartesian"]
MAX_FILE_BYTES = 256 * 1024 * 1024
MAX_POINTS = 2_000_000
_SPLIT = re.compile(r"[\s,]+")


class ToolPathError(ValueError):
    """The tool-path file cannot be streamed; the message names the file and line."""


@dataclass(frozen=True)
class ToolPath:
    """Points in SI: joints in rad, or x y z (m) and A B C (rad)."""

    space: Space
    points: NDArray[np.float64]  # shape (n, 6)
    source: str = "<memory>"
    lines: tuple[int, ...] = ()  # the file line of each point, for messages

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def where(self, i: int) -> str:
        return f"{self.source}:{self.lines[i]}" if self.lines else f"{self.source} point {i + 1}"


def parse_tool_path(text: str, space: Space, source: str = "<string>") -> ToolPath:
    """Read the points of a tool-path text (see the module docstring)."""
    if space not in ("joint", "cartesian"):
        raise ToolPathError(f"{source}: space must be 'joint' or 'cartesian', not {space!r}")
    rows: list[list[float]] = []
    lines: list[int] = []
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        parts = [p for p in _SPLIT.split(body) if p]
        if len(parts) != 6:
            raise ToolPathError(f"{source}:{number}: expected 6 values, found {len(parts)}")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise ToolPathError(f"{source}:{number}: not a number in {body!r}") from None
        if not all(math.isfinite(v) for v in values) or any("_" in p for p in parts):
            raise ToolPathError(f"{source}:{number}: values must be finite decimal numbers")
        rows.append(values)
        lines.append(number)
        if len(rows) > MAX_POINTS:
            raise ToolPathError(f"{source}:{number}: more than {MAX_POINTS} points")
    if not rows:
        raise ToolPathError(f"{source}: no points")
    raw = np.array(rows, dtype=float)
    if space == "joint":
        points = np.radians(raw)
    else:
        points = np.column_stack((raw[:, :3] / 1000.0, np.radians(raw[:, 3:])))
    return ToolPath(space, points, source, tuple(lines))


def load_tool_path(path: str | Path, space: Space) -> ToolPath:
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ToolPathError(f"{path}: {size} bytes, more than the {MAX_FILE_BYTES} allowed")
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ToolPathError(f"{path}: cannot read tool path: {error.strerror or error}") from None
    except UnicodeDecodeError as error:
        raise ToolPathError(f"{path}: not UTF-8 text ({error.reason} at byte {error.start})") from None
    return parse_tool_path(text, space, str(path))


def check_tool_path(
    path: ToolPath,
    dt: float,
    *,
    lower: NDArray[np.float64] | None = None,
    upper: NDArray[np.float64] | None = None,
    max_joint_speed: NDArray[np.float64] | None = None,
    max_speed: float = 2.0,
    max_angular_speed: float = math.pi,
    start: NDArray[np.float64] | None = None,
) -> None:
    """Refuse a path the robot cannot follow one point per cycle ``dt`` (raises ToolPathError).

    ``start`` is where the robot is (same units as the points): the first point must be
    reachable from it within one cycle too.
    """
    pts = path.points if start is None else np.vstack((np.asarray(start, dtype=float), path.points))
    offset = 0 if start is None else 1
    if path.space == "joint":
        if lower is not None and upper is not None:
            outside = np.nonzero(np.any((path.points < lower - 1e-9) | (path.points > upper + 1e-9), axis=1))[0]
            if outside.size:
                i = int(outside[0])
                raise ToolPathError(f"{path.where(i)}: point {np.degrees(path.points[i]).round(3).tolist()} deg is outside the joint limits")
        if max_joint_speed is not None and len(pts) > 1:
            speed = np.abs(np.diff(pts, axis=0)) / dt
            over = np.nonzero(np.any(speed > max_joint_speed * (1 + 1e-9), axis=1))[0]
            if over.size:
                j = int(over[0])
                _too_fast(path, j + 1 - offset, f"{math.degrees(float(np.max(speed[j]))):.1f} deg/s on an axis")
        return
    if len(pts) > 1:
        linear = np.linalg.norm(np.diff(pts[:, :3], axis=0), axis=1) / dt
        over = np.nonzero(linear > max_speed * (1 + 1e-9))[0]
        if over.size:
            j = int(over[0])
            _too_fast(path, j + 1 - offset, f"{linear[j]:.3f} m/s (limit {max_speed:g})")
        rotations = [abc_to_matrix(*p[3:]) for p in pts]
        for i in range(1, len(rotations)):
            turn = rotation_angle(rotations[i] @ rotations[i - 1].T) / dt
            if turn > max_angular_speed * (1 + 1e-9):
                _too_fast(path, i - offset, f"{turn:.3f} rad/s (limit {max_angular_speed:g})")


def _too_fast(path: ToolPath, i: int, what: str) -> None:
    """The step into path point ``i`` is too fast (``i`` = 0: from where the robot is to the first point)."""
    if i == 0:
        raise ToolPathError(f"{path.where(0)}: the first point is too far from where the robot is ({what} in one cycle)")
    raise ToolPathError(f"{path.where(i)}: the step to this point needs {what}; the path must move at most that far per cycle")
