"""Cell model files: load one, validate one, check its joint poses against a robot.

The model itself is :mod:`execution_engine.app_model.cell_model`, the reading of the XML
:mod:`execution_engine.app_model.cell_reader`; this module is the entry point the rest of the
program (and the tests) use, and keeps their names importable from one place.
"""
from __future__ import annotations

from pathlib import Path

from core_functions.robots import RobotModel
from execution_engine.app_model import wire_fit
from execution_engine.app_model.cell_model import Cell, Element, Frame, JointPose, check_joint_poses
from execution_engine.app_model.cell_reader import CellReader
from execution_engine.app_model.diagnostics import ApplicationError, Diagnostic, DiagnosticLog, capped
from execution_engine.app_model.frame_tree import WORLD
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES
from execution_engine.app_model.structure import read_structured

__all__ = [
    "WORLD", "Cell", "Element", "Frame", "JointPose", "check_joint_poses", "load_cell", "read_cell", "read_cell_log", "validate_cell",
]


def read_cell_log(
    path: Path, *, display: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES, fits: bool = True,
) -> tuple[Cell | None, DiagnosticLog]:
    """The cell at ``path`` (None when it has errors) and the log of its problems (uncapped
    counts, for a caller that merges them into a larger report).

    ``fits`` also checks that it can run (wire_fit.check_cell: its snapshot fits in a message,
    every frame within the bounds in the world), with the problem at the cell's root; an
    application checks that itself, once its robot is known, at its ``cell=``."""
    doc, log = read_structured(Path(path), "cell", display=display, max_bytes=max_bytes)
    if doc is None:
        return None, log
    structure_ok = not log.has_errors
    cell = CellReader(doc, log).read(structure_ok)
    if cell is not None and fits:
        offsets = doc.source.tag_offsets()
        root = doc.source.at_offset(offsets[0] if offsets else 0)
        wire_fit.check_cell(cell, root, doc.file, log)
    return (cell if not log.has_errors else None), log


def read_cell(path: Path, *, display: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[Cell | None, list[Diagnostic]]:
    """The cell at ``path`` (None when it has errors) and every diagnostic, sorted and capped."""
    cell, log = read_cell_log(path, display=display, max_bytes=max_bytes)
    return cell, capped(log)


def load_cell(path: Path | str, *, max_bytes: int = DEFAULT_MAX_BYTES) -> Cell:
    """The cell at ``path``; ApplicationError with every problem if it is not valid."""
    cell, diagnostics = read_cell(Path(path), max_bytes=max_bytes)
    if cell is None:
        raise ApplicationError(diagnostics)
    return cell


def validate_cell(path: Path | str, robot: RobotModel | None = None, *, max_bytes: int = DEFAULT_MAX_BYTES) -> list[Diagnostic]:
    """Every problem of the cell file; joint poses are checked too when ``robot`` is given."""
    cell, log = read_cell_log(Path(path), max_bytes=max_bytes)
    if cell is not None and robot is not None:
        log.extend(check_joint_poses(cell, robot))
    return capped(log)
