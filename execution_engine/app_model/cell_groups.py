"""The schema check of an application on a cell of several robots whose groups the cell names.

application.xsd lists the group elements an operation may hold: every robot model's own groups.
A cell may name its robots' groups for itself (``<robot prefix="viper_">``: ``<viper_arm>``), which
no fixed schema can list; such an application's operations are checked again against the schema
with the cell's group names added (:func:`execution_engine.app_model.schema.application_schema_with`),
so a misspelt group or a misplaced element is reported as in any application.  Only a document the
plain schema refused, on ``robot="cell"``, is looked at again: any other is read as before.
"""
from __future__ import annotations

from core_functions.cell_robots import CELL_ROBOT
from execution_engine.app_model.cell import read_cell_log
from execution_engine.app_model.diagnostics import DiagnosticLog
from execution_engine.app_model.reader import GROUP_TAGS
from execution_engine.app_model.safe_xml import XmlDocument
from execution_engine.app_model.schema import application_schema_with
from execution_engine.app_model.structure import validate_structure


def cell_structure(doc: XmlDocument, log: DiagnosticLog) -> DiagnosticLog:
    """``log`` (the plain schema's verdict on ``doc``), or the verdict of the schema that also takes the
    groups ``doc``'s cell names, when ``doc`` runs on a cell that names groups of its own."""
    root = doc.root
    cell_name = (root.get("cell") or "").strip()
    if not log.has_errors or root.get("robot") != CELL_ROBOT or not cell_name:
        return log
    cell, _ = read_cell_log(doc.path.parent / cell_name, fits=False)  # its own problems are reported where the application reads it
    if cell is None:
        return log
    groups = frozenset(group for robot in cell.robots for group in robot.groups)
    if groups <= GROUP_TAGS:
        return log
    return validate_structure(doc, application_schema_with(groups))
