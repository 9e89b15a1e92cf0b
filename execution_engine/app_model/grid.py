"""The frames of a pallet grid, as ``<for_each in="grid:ORIGIN ROWSxCOLUMNS ROW_PITCH COLUMN_PITCH">`` asks.

A tray or a pallet is a grid of pockets: writing a frame per pocket in the cell is tedious and
error-prone, and a grid is what the integrator measures (the first pocket, the pitches).  The
grid's frames are children of the origin frame -- locating the origin with a camera corrects every
pocket -- with its orientation and kind and its free attributes (the ``element`` a pocket holds),
``ORIGIN_ROW_COLUMN`` by name: row r, column c sits (r-1) row pitches along the origin's x and
(c-1) column pitches along its y.  The origin's own ``box`` is not copied (the tray is one solid).
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from core_functions import limits
from core_functions.geometry import Pose
from execution_engine.app_model.cell_model import Frame
from execution_engine.app_model.diagnostics import Location

PREFIX = "grid:"
#: Frames one grid may make: a pallet of 100 x 100 is far beyond any tray.
MAX_GRID_FRAMES = 10_000
_SIZE = re.compile(r"^(\d{1,6})\s*[xX×]\s*(\d{1,6})$")
_PITCH = re.compile(r"^([-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?)\s*(m|mm|cm)?$")
_FACTORS = {"m": 1.0, "mm": 0.001, "cm": 0.01, None: 1.0}
_NOT_COPIED = frozenset({"box", "box_xyz"})
FORM = "grid:ORIGIN ROWSxCOLUMNS ROW_PITCH COLUMN_PITCH, e.g. grid:tray_origin 3x4 0.020 0.025"


class GridError(ValueError):
    """A grid spec that cannot be made; the message names the field at fault."""


@dataclass(frozen=True)
class Grid:
    """A parsed grid: the origin frame, rows and columns, the pitches (m) along the origin's x and y."""

    origin: str
    rows: int
    columns: int
    row_pitch: float
    column_pitch: float

    def names(self) -> list[str]:
        """The frames' names, row by row: ``ORIGIN_1_1, ORIGIN_1_2, ...``."""
        return [f"{self.origin}_{r}_{c}" for r in range(1, self.rows + 1) for c in range(1, self.columns + 1)]

    def frames(self, origin: Frame, where: Location | None) -> dict[str, Frame]:
        attributes = {k: v for k, v in origin.attributes.items() if k not in _NOT_COPIED}
        made: dict[str, Frame] = {}
        for r in range(self.rows):
            for c in range(self.columns):
                name = f"{self.origin}_{r + 1}_{c + 1}"
                local = Pose(x=r * self.row_pitch, y=c * self.column_pitch)
                made[name] = Frame(name, self.origin, local, origin.kind, attributes, None, where)
        return made


def parse_grid(spec: str) -> Grid:
    """The grid a ``grid:`` spec describes (the text after ``grid:``); GridError names the field."""
    fields = spec.split()
    if len(fields) != 4:
        raise GridError(f"grid needs 4 fields, got {len(fields)}: {FORM}")
    origin, size, row_pitch, column_pitch = fields
    match = _SIZE.match(size)
    if match is None:
        raise GridError(f"grid size {size!r} is not ROWSxCOLUMNS (whole numbers, e.g. 3x4)")
    rows, columns = int(match.group(1)), int(match.group(2))
    if rows < 1 or columns < 1:
        raise GridError(f"grid size {size!r}: rows and columns must be 1 or more")
    if rows * columns > MAX_GRID_FRAMES:
        raise GridError(f"grid size {size!r} makes {rows * columns:,} frames, more than the limit of {MAX_GRID_FRAMES:,}")
    return Grid(origin, rows, columns, _pitch("row pitch", row_pitch, rows), _pitch("column pitch", column_pitch, columns))


def _pitch(field: str, text: str, count: int) -> float:
    match = _PITCH.match(text)
    if match is None:
        raise GridError(f"grid {field} {text!r} is not a length (metres, or a number with m, cm or mm)")
    factor = _FACTORS[match.group(2)]
    written = float(match.group(1))
    problem = limits.LENGTH.violation(f"grid {field}", written, factor, match.group(2) or "m")
    if problem is None and count > 1:
        problem = limits.LENGTH.violation(f"grid {field} x {count - 1}", written * (count - 1), factor, match.group(2) or "m")
    if problem is not None:
        raise GridError(problem)
    if written == 0 and count > 1:
        raise GridError(f"grid {field} is 0: the {count} {'rows' if field.startswith('row') else 'columns'} would be one place")
    return written * factor


def grid_frames(spec: str, frames: Mapping[str, Frame], where: Location | None) -> dict[str, Frame]:
    """The frames of the grid ``spec`` over the cell's ``frames``; GridError names the field at fault."""
    grid = parse_grid(spec)
    origin = frames.get(grid.origin)
    if origin is None:
        raise GridError(f"grid origin {grid.origin!r} is not a frame of the cell")
    made = grid.frames(origin, where)
    for name, frame in made.items():
        existing = frames.get(name)
        if existing is not None and (existing.parent, existing.local) != (frame.parent, frame.local):
            raise GridError(f"grid frame {name!r} would replace the cell's frame of that name{_written(existing)}")
    return made


def _written(frame: Frame) -> str:
    return f" ({frame.location.file}:{frame.location.line})" if frame.location is not None else ""
