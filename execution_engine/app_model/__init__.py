"""The application model: application and cell XML files, loaded safely and validated.

Use :func:`load_application` to get a checked :class:`Application` (or an
:class:`ApplicationError` listing every problem as ``FILE:LINE:COL: message``), and
:func:`validate_application` to get the diagnostics only.  docs/application_xml.md describes both
file formats.
"""
from execution_engine.app_model.application import load_application, read_application, validate_application
from execution_engine.app_model.cell import Cell, Element, Frame, JointPose, check_joint_poses, load_cell, read_cell, validate_cell
from execution_engine.app_model.diagnostics import MAX_DIAGNOSTICS, ApplicationError, Diagnostic, Location, Omitted, count_problems
from execution_engine.app_model.model import WAIT, Application, Call, ErrorPolicy, Operation
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, MAX_ELEMENTS

__all__ = [
    "DEFAULT_MAX_BYTES",
    "MAX_DIAGNOSTICS",
    "MAX_ELEMENTS",
    "WAIT",
    "Application",
    "ApplicationError",
    "Call",
    "Cell",
    "Diagnostic",
    "Element",
    "ErrorPolicy",
    "Frame",
    "JointPose",
    "Location",
    "Omitted",
    "Operation",
    "check_joint_poses",
    "count_problems",
    "load_application",
    "load_cell",
    "read_application",
    "read_cell",
    "validate_application",
    "validate_cell",
]
