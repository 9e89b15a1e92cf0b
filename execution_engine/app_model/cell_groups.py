"""The schema check of an application on a cell of several robots whose groups the cell names.

application.xsd lists the group elements an operation may hold: every robot model's own groups.
A cell may name its robots' groups for itself (``<robot prefix="viper_">``: ``<viper_arm>``), which
no fixed schema can list; such an application's operations are checked again against the schema
with the cell's group names added (:func:`execution_engine.app_model.schema.application_schema_with`),
so a misspelt group or a misplaced element is reported as in any application.  Only a document the
plain schema refused, on ``robot="cell"``, is looked at again: any other is read as before.
"""
from __future__ import annotations

from pathlib import Path

from core_functions.cell_robots import CELL_ROBOT, CellNames, cell_group_names
from execution_engine.app_model.cell import read_cell_log
from execution_engine.app_model.diagnostics import DiagnosticLog
from execution_engine.app_model.reader import GROUP_TAGS
from execution_engine.app_model.safe_xml import XmlDocument, read_xml
from execution_engine.app_model.schema import application_schema_with
from execution_engine.app_model.structure import validate_structure


def cell_structure(doc: XmlDocument, log: DiagnosticLog) -> DiagnosticLog:
    """``log`` (the plain schema's verdict on ``doc``), or the verdict of the schema that also takes the
    groups ``doc``'s cell names, when ``doc`` runs on a cell that names groups of its own."""
    root = doc.root
    cell_name = (root.get("cell") or "").strip()
    if not log.has_errors or root.get("robot") != CELL_ROBOT or not cell_name:
        return log
    path = doc.path.parent / cell_name
    cell, _ = read_cell_log(path, fits=False)  # its own problems are reported where the application reads it
    groups = frozenset(group for robot in cell.robots for group in robot.groups) if cell is not None else written_groups(path)
    if groups <= GROUP_TAGS:
        return log
    return validate_structure(doc, application_schema_with(groups))


def written_groups(path: Path) -> frozenset[str]:
    """The group names a cell file with errors gives its robots, as far as they can be read: its problems are
    reported at their lines already, and an application naming those groups is not told they do not exist."""
    cell, _ = read_xml(path)
    groups: set[str] = set()
    for robot in cell.root.iterfind("robot") if cell is not None else ():
        renamed = tuple((own, named) for own, named in ((g.get("name"), g.get("as")) for g in robot.iterfind("group")) if own and named)
        groups.update(cell_group_names(robot.get("model", ""), CellNames(robot.get("prefix", ""), renamed)))
    return frozenset(groups)
