"""The builder's server side (paper Figure 7): the catalog, the cell's names, validation placed at cells, open and save.

The page edits a :class:`~operator_station.blocks.BlockDocument` (operations, and the loops and
calls around them; a flat one is an :class:`~execution_engine.app_model.document.AppDocument`,
written in the paper's Figure 6 layout, a tree is written through lxml); every check is the
project's own validator (:func:`execution_engine.app_model.read_application`) run on the XML
the document would be saved as, read as if it were the file at its path (so the cell file is
found beside it).  Each message is then placed at the operation, group and param of the line it
names, through the serializer's line map: the page shows it at that cell of the table.
"""
from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

from cell_runner.catalog_document import catalog_document
from cell_runner.output_files import FilePlan, Output, Refused
from core_functions.catalog import Catalog
from core_functions.cell_robots import CELL_ROBOT, cell_robot_model
from core_functions.robots import find_robot
from execution_engine.app_model import Application, Diagnostic, read_application
from execution_engine.app_model.cell import read_cell
from execution_engine.app_model.document import AppDocument, OperationEntry, Placement, parse_document, serialize
from operator_station.blocks import BlockDocument, walk
from operator_station.blocks_xml import Where, read_blocks, write_blocks


@dataclass(frozen=True)
class PlacedMessage:
    """One validator message and the cell of the builder it belongs to."""

    message: str
    severity: str
    file: str
    line: int
    col: int
    operation: int | None  # index into the document's operations (all of them, in document order); None: the application or its cell file
    group: str | None
    param: int | None
    part: str
    step: list[int] | None = None  # the step's path in the tree of blocks (a flat document: [operation]); None as operation


    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def catalog_view(catalog: Catalog) -> dict[str, Any]:
    """``functions --json`` with the functions grouped by library: core first, then each application library."""
    document = catalog_document(catalog)
    libraries: dict[str, list[dict[str, Any]]] = {}
    for function in document["functions"]:  # type: ignore[attr-defined]
        libraries.setdefault(function["library"], []).append(function)
    document["libraries"] = [{"name": name, "kind": "core" if name == "core" else "app", "functions": [f["name"] for f in functions]}
                             for name, functions in sorted(libraries.items(), key=lambda kv: (kv[0] != "core", kv[0]))]
    return document


def cell_names(document: AppDocument, path: Path) -> dict[str, Any]:
    """The names the cell offers to params (frames with their kind, elements, joint poses) and the robot's groups.

    A cell that cannot be read offers nothing and says why (validation says it at its line too).
    """
    try:
        robot = find_robot(document.robot)
        groups = list(robot.group_names)
        poses = sorted(robot.poses)
        cameras = list(robot.cameras)
    except KeyError:
        groups, poses, cameras = [], [], []
    out: dict[str, Any] = {"groups": groups, "robot_poses": poses, "cameras": cameras, "frames": [], "elements": [], "joint_poses": [], "problem": None}
    if not document.cell:
        return out
    cell_path = (path.parent / document.cell).resolve()
    cell, problems = read_cell(cell_path, display=document.cell)
    if cell is None:
        out["problem"] = str(problems[0]) if problems else f"cannot read {document.cell}"
        return out
    if document.robot == CELL_ROBOT and cell.robots:  # a mixed cell: its robots' groups, poses and cameras
        robot = cell_robot_model(cell.name, cell.robots)
        out.update(groups=list(robot.group_names), robot_poses=sorted(robot.poses), cameras=list(robot.cameras))
    out["frames"] = [{"name": f.name, "kind": f.kind} for f in cell.frames.values()]
    out["elements"] = [{"name": e.name, "kind": e.kind} for e in cell.elements.values()]
    out["joint_poses"] = [{"name": p.name, "group": p.group} for p in cell.joint_poses.values()]
    return out


def place(diagnostics: list[Diagnostic], placements: list[Placement], display: str) -> list[PlacedMessage]:
    """Each diagnostic with the cell of its line (messages of other files, the cell's, stay at the application)."""
    out = []
    for d in diagnostics:
        where = placements[d.line - 1] if d.file == display and 0 < d.line <= len(placements) else Placement()
        step = None if where.operation is None else [where.operation]
        out.append(PlacedMessage(d.message, d.severity, d.file, d.line, d.col, where.operation, where.group, where.param, where.part, step))
    return out


def place_steps(diagnostics: list[Diagnostic], lines: list[Where], document: BlockDocument, display: str) -> list[PlacedMessage]:
    """Each diagnostic at the step of its line; one of a called file (``... called from FILE:LINE:COL``) at that call."""
    leaves: dict[tuple[int, ...], int] = {}
    walk(document.body, lambda step, path: leaves.setdefault(path, len(leaves)) if isinstance(step, OperationEntry) else None)
    called_from = re.compile(rf"called from {re.escape(display)}:(\d+):")
    out = []
    for d in diagnostics:
        line = d.line if d.file == display else None
        if line is None and (match := called_from.search(d.message)):
            line = int(match.group(1))
        where = lines[line - 1] if line is not None and 0 < line <= len(lines) else Where()
        if d.file != display:
            where = Where(where.step, part=where.part)  # the call's row, not a cell of its own file's
        operation = leaves.get(where.step) if where.step is not None else None
        out.append(PlacedMessage(d.message, d.severity, d.file, d.line, d.col, operation, where.group, where.param, where.part,
                                 None if where.step is None else list(where.step)))
    return out


def _application_message(text: str, path: Path) -> PlacedMessage:
    return PlacedMessage(text, "error", str(path), 1, 1, None, None, None, "application")


def validate(document: AppDocument | BlockDocument, path: Path, catalog: Catalog) -> tuple[Application | None, list[PlacedMessage], str]:
    """Validate the document as the file at ``path``: the application (None with errors), the placed messages, the XML.

    A BlockDocument holds the loops and calls of its file: it is checked as written, expanded.  What
    a file holds that the builder does not (:attr:`BlockDocument.unheld`: an ``<if>``, a comment inside
    a call's params) is never dropped: unchanged, the file itself is checked and run; edited, it is
    refused naming what it would lose.  An AppDocument (the flat document of ``read_document``) of a
    file of loops holds only its top-level operations, and is refused the same way when edited.
    DocumentError: the document holds what XML cannot carry (a group that is not a name)."""
    display = str(path)
    if isinstance(document, BlockDocument):
        kept = held_back(path)
        if kept is not None:
            if _same(kept, document):
                app, diagnostics = read_application(path, catalog)
                return app, place(diagnostics, [], display), write_blocks(kept)[0]
            return None, [_application_message(_unheld(path, kept, "an edit cannot be checked, run or saved without them; edit the file as text"), path)], ""
        if not document.is_flat():
            text, lines = write_blocks(document)
            app, diagnostics = read_application(path, catalog, data=text.encode("utf-8"))
            return app, place_steps(diagnostics, lines, document, display), text
        document = document.flat()
    text, placements = serialize(document)
    on_disk = with_steps(path)
    if on_disk is not None:
        if replace(on_disk, steps=[]) == replace(document, steps=[]):
            app, diagnostics = read_application(path, catalog)
            return app, place(diagnostics, [], display), text
        refusal = (f"{path} holds {', '.join(on_disk.steps)}, which the builder does not show: an edit of the rest cannot be "
                   "checked, run or saved with them; edit the file as text")
        return None, [PlacedMessage(refusal, "error", display, 1, 1, None, None, None, "application")], text
    app, diagnostics = read_application(path, catalog, data=text.encode("utf-8"))
    return app, place(diagnostics, placements, display), text


def _same(kept: BlockDocument, document: BlockDocument) -> bool:
    return replace(kept, unheld=[]) == replace(document, unheld=[])


def _unheld(path: Path, kept: BlockDocument, consequence: str) -> str:
    return f"{path} holds {', '.join(kept.unheld)}, which the builder does not hold: {consequence}"


def held_back(path: Path) -> BlockDocument | None:
    """The block document of the file at ``path`` when it holds something the builder does not, else None."""
    document, _ = _opened(path)
    return document if document is not None and document.unheld else None


def _opened(path: Path) -> tuple[BlockDocument | None, list[Diagnostic]]:
    """The file's block document, read once per change of the file (by its mtime and size): the page opens it, then
    validates on every edit, and a 10,000-operation file takes a second to read.  Shared: never changed in place."""
    try:
        info = path.stat()
    except OSError as error:
        return None, [Diagnostic(str(path), 1, 1, f"cannot read the file: {error.strerror or error}")]
    return _read_once(path, info.st_mtime_ns, info.st_size)


@lru_cache(maxsize=4)
def _read_once(path: Path, mtime_ns: int, size: int) -> tuple[BlockDocument | None, list[Diagnostic]]:
    return read_blocks(path)


def with_steps(path: Path) -> AppDocument | None:
    """The document of the file at ``path`` when it has loops or calls, else None (looked for in the bytes first:
    the page validates on every edit)."""
    try:
        data = path.read_bytes() if path.is_file() else b""
    except OSError:
        return None
    if b"<for_each" not in data and b"<repeat" not in data and b"<call" not in data:
        return None
    document, _ = parse_document(data, path)
    return document if document is not None and document.steps else None


def open_document(path: Path) -> tuple[BlockDocument | None, list[Diagnostic]]:
    """The file as the builder shows it: its operations, loops and calls as blocks."""
    return _opened(path)


def save_document(document: AppDocument | BlockDocument, path: Path, catalog: Catalog, outputs: Sequence[Output] = ()) -> tuple[bool, list[PlacedMessage]]:
    """Write the document to ``path`` only if it validates there; the messages either way.

    ``path`` may be the application itself (that is saving), never its cell nor one of
    ``outputs`` (the station's runs' files): run's rule, :mod:`cell_runner.output_files`.
    The file is replaced atomically (a temporary file beside it, then a rename), so a crash
    never leaves half an application behind.
    """
    app, messages, text = validate(document, path, catalog)
    if app is None:
        return False, messages
    kept = held_back(path)
    if isinstance(document, BlockDocument) and kept is not None:  # unchanged, it validated as the file: saving would drop the rest
        return False, [*messages, _application_message(_unheld(path, kept, "saving would drop them; edit the file as text, or save under another name"), path)]
    on_disk = with_steps(path) if isinstance(document, AppDocument) else None
    if on_disk is not None:  # an AppDocument holds no loops or calls: saving would drop them
        refusal = (f"{path} holds {', '.join(on_disk.steps)}, which the builder does not show: saving would drop them; "
                   "edit the file as text, or save under another name")
        return False, [*messages, PlacedMessage(refusal, "error", str(path), 1, 1, None, None, None, "application")]
    plan = FilePlan("application")
    if app.cell is not None and app.cell.path is not None:
        plan.read(f"the cell {app.cell.path}", app.cell.path)
    for output in (*outputs, Output("save as", str(path), "the application", "app.xml")):
        plan.write(output)
    try:
        plan.check_clashes()
    except Refused as refusal:
        return False, [*messages, PlacedMessage(str(refusal), "error", str(path), 1, 1, None, None, None, "application")]
    temporary = path.with_name(f".{path.name}.studio-{os.getpid()}")
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, path)
    return True, messages
