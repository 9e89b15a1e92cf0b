"""Load and validate an application file: safe parse, schema, robot, cell, catalog, plausibility.

One entry point for the CLI's ``validate`` and for the engine: every problem of the application
and of its cell file is collected and reported at once, sorted by file, line and column.
"""
from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import MappingProxyType

from core_functions.catalog import Catalog
from execution_engine.app_model.cell import Cell, check_joint_poses, read_cell
from execution_engine.app_model.diagnostics import ApplicationError, Diagnostic, has_errors, sorted_diagnostics
from execution_engine.app_model.model import Application, Call, Operation
from execution_engine.app_model.positions import SourceMap
from execution_engine.app_model.reader import ApplicationDraft, ApplicationReader, OperationSite
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES
from execution_engine.app_model.schema import read_structured
from execution_engine.app_model.validation import ApplicationChecker, CheckedCall


@contextmanager
def _no_gc_pauses() -> Iterator[None]:
    """Loading allocates ~10 objects per element and frees none of them until the end, so the
    cyclic GC would only rescan a growing heap (a third of the time of a 10,000-operation file);
    nothing here makes reference cycles that need it.  The previous state is restored."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def read_application(
    path: Path | str, catalog: Catalog, *, max_bytes: int = DEFAULT_MAX_BYTES
) -> tuple[Application | None, list[Diagnostic]]:
    """The application (None if it has errors) and every diagnostic of it and its cell, sorted."""
    with _no_gc_pauses():
        return _read_application(Path(path), catalog, max_bytes)


def _read_application(path: Path, catalog: Catalog, max_bytes: int) -> tuple[Application | None, list[Diagnostic]]:
    doc, diagnostics = read_structured(path, "application", max_bytes=max_bytes)
    if doc is None:
        return None, sorted_diagnostics(diagnostics)
    reader = ApplicationReader(doc)
    draft = reader.read()
    diagnostics.extend(reader.diagnostics)
    cell, cell_broken = _read_cell(draft, diagnostics, max_bytes)
    robot = draft.robot
    if robot is None:
        return None, sorted_diagnostics(diagnostics)
    if cell is not None:
        diagnostics.extend(check_joint_poses(cell, robot))
        cell = cell.bind(robot)
    checker = ApplicationChecker(draft, robot, catalog, cell, cell_broken)
    checked = checker.check()
    policy = checker.check_policy(draft.policy)
    diagnostics.extend(checker.diagnostics)
    diagnostics = sorted_diagnostics(diagnostics)
    if has_errors(diagnostics):
        return None, diagnostics
    application = Application(
        name=draft.name,
        path=path,
        robot=robot,
        cell=cell,
        error_policy=policy,
        operations=tuple(_freeze(op_site, calls, draft.source) for op_site, calls in zip(draft.operations, checked)),
        description=draft.description,
        version=draft.version,
    )
    return application, diagnostics


def _read_cell(draft: ApplicationDraft, diagnostics: list[Diagnostic], max_bytes: int) -> tuple[Cell | None, bool]:
    """The application's cell, and whether it was named but could not be loaded."""
    if draft.cell_path is None or draft.cell_where is None:
        return None, False
    if not draft.cell_path.is_file():
        diagnostics.append(Diagnostic.at(draft.cell_where, f"cell file {draft.cell_display} not found (looked for {draft.cell_path.resolve()})"))
        return None, True
    cell, cell_diagnostics = read_cell(draft.cell_path, display=draft.cell_display, max_bytes=max_bytes)
    diagnostics.extend(cell_diagnostics)
    if cell is None:
        diagnostics.append(Diagnostic.at(draft.cell_where, f"cell file {draft.cell_display} has errors (listed with its name); references to its frames are not checked until they are fixed"))
        return None, True
    return cell, False


def _freeze(site: OperationSite, calls: list[CheckedCall], source: SourceMap) -> Operation:
    frozen: dict[str, Call] = {}
    for checked in calls:
        line, col = source.line_col(checked.site.at)
        frozen[checked.site.group] = Call(
            group=checked.site.group,
            function=checked.site.function,
            params=checked.params or (),
            implicit=checked.site.implicit,
            file=source.file,
            line=line,
            col=col,
        )
    line, col = source.line_col(site.at)
    return Operation(id=site.id, name=site.name, line=line, col=col, calls=MappingProxyType(frozen))


def load_application(path: Path | str, catalog: Catalog, *, max_bytes: int = DEFAULT_MAX_BYTES) -> Application:
    """The validated application; ApplicationError carrying every diagnostic if it has errors."""
    application, diagnostics = read_application(path, catalog, max_bytes=max_bytes)
    if application is None:
        raise ApplicationError(diagnostics or [Diagnostic(str(path), 1, 1, "invalid application")])
    return application


def validate_application(path: Path | str, catalog: Catalog, *, max_bytes: int = DEFAULT_MAX_BYTES) -> list[Diagnostic]:
    """Every problem (errors and warnings) of the application and its cell; empty when it is clean."""
    return read_application(path, catalog, max_bytes=max_bytes)[1]
