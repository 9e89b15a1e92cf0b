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
from execution_engine.app_model import wire_fit
from execution_engine.app_model.cell import Cell, check_joint_poses, read_cell_log
from execution_engine.app_model.cell_groups import cell_structure
from execution_engine.app_model.branches import check_branches
from execution_engine.app_model.expand import Expander, merge_iterations
from execution_engine.app_model.expanded_source import ExpandedSource
from execution_engine.app_model.flag_check import check_waits
from execution_engine.app_model.diagnostics import ApplicationError, Diagnostic, DiagnosticLog, capped, has_errors
from execution_engine.app_model.model import WAIT, Application, Call, ErrorPolicy, Operation
from execution_engine.app_model.reader import ApplicationDraft, ApplicationReader
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES
from execution_engine.app_model.structure import read_structured
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
    path: Path | str, catalog: Catalog, *, max_bytes: int = DEFAULT_MAX_BYTES, data: bytes | None = None
) -> tuple[Application | None, list[Diagnostic]]:
    """The application (None if it has errors) and every diagnostic of it and its cell, sorted.

    ``data``: an edited content not saved yet, checked as if it were the file at ``path`` (its
    cell file is looked for beside ``path``)."""
    with _no_gc_pauses():
        return _read_application(Path(path), catalog, max_bytes, data)


def _read_application(path: Path, catalog: Catalog, max_bytes: int, data: bytes | None = None) -> tuple[Application | None, list[Diagnostic]]:
    doc, log = read_structured(path, "application", max_bytes=max_bytes, data=data)
    if doc is None:
        return None, capped(log)
    log = cell_structure(doc, log)
    draft = ApplicationReader(doc, log).read()
    draft.source.detach()  # the drafts hold offsets, not elements: the tree can go before the cell and the checks
    del doc
    cell, cell_broken = _read_cell(draft, log, max_bytes)
    robot = draft.robot
    if robot is None:
        return None, capped(log)
    includes: tuple[Path, ...] = ()
    expander: Expander | None = None
    if draft.has_steps or "{" in draft.source.text:  # loops or calls, or a {variable} outside any
        expander = Expander(draft, cell, cell_broken, log, lambda p, shown, own: _read_called(p, shown, own, max_bytes), path)
        draft.operations, cell = expander.expand()
        draft.source = expander.source
        includes = tuple(expander.includes)
    if cell is not None:
        joint_problems = check_joint_poses(cell, robot)
        log.extend(joint_problems)
        cell = cell.bind(robot)
        if not has_errors(joint_problems) and draft.cell_where is not None:
            wire_fit.check_cell(cell, draft.cell_where, draft.cell_display or "", log)
    checker = ApplicationChecker(draft, robot, catalog, cell, cell_broken, log)
    checked = checker.check()
    policy = checker.check_policy(draft.policy)
    _check_requests(draft, checked, catalog, cell, policy, log)
    check_waits(draft, checked, catalog, log, cell)
    if expander is not None:
        check_branches(expander.branches, draft, catalog, log)
        merge_iterations(log, expander.source.contexts, expander.unsubstituted)
    if log.has_errors:
        return None, capped(log)
    application = Application(
        name=draft.name,
        path=path,
        robot=robot,
        cell=cell,
        error_policy=policy,
        operations=_freeze(draft, checked),
        description=draft.description,
        version=draft.version,
        sync=draft.sync,
        includes=includes,
    )
    return application, capped(log)


def _read_called(path: Path, display: str, log: DiagnosticLog, max_bytes: int) -> ApplicationDraft | None:
    """A called application's steps, read as the application itself is (its problems in ``log``)."""
    doc, own = read_structured(path, "application", display=display, max_bytes=max_bytes)
    if doc is not None:
        own = cell_structure(doc, own)
    log.merge(own)
    if doc is None:
        return None
    draft = ApplicationReader(doc, log).read()
    draft.source.detach()
    return draft


def _read_cell(draft: ApplicationDraft, log: DiagnosticLog, max_bytes: int) -> tuple[Cell | None, bool]:
    """The application's cell, and whether it was named but could not be loaded."""
    if draft.cell_path is None or draft.cell_where is None:
        return None, False
    if not draft.cell_path.is_file():
        log.append(Diagnostic.at(draft.cell_where, f"cell file {draft.cell_display} not found (looked for {draft.cell_path.resolve()})"))
        return None, True
    cell, cell_log = read_cell_log(draft.cell_path, display=draft.cell_display, max_bytes=max_bytes, fits=False)
    log.merge(cell_log)
    if cell is None:
        log.append(Diagnostic.at(draft.cell_where, f"cell file {draft.cell_display} has errors (listed with its name); references to its frames are not checked until they are fixed"))
        return None, True
    return cell, False


def _check_requests(
    draft: ApplicationDraft, checked: list[list[CheckedCall]], catalog: Catalog, cell: Cell | None, policy: ErrorPolicy, log: DiagnosticLog,
) -> None:
    """Every call's request fits the transport (wire_fit); implicit waits send none."""
    assert draft.robot is not None

    def calls() -> Iterator[tuple[str, str, str, tuple[str, ...], int]]:
        for operation, group_calls in zip(draft.operations, checked):
            for call in group_calls:
                if not call.site.implicit:
                    yield operation.id, call.site.group, call.site.function, call.params or (), call.site.at

    longest = (
        max((len(op.id) for op in draft.operations), default=0),
        max(len(WAIT), *map(len, catalog.functions)),  # the built-in wait, when the catalog has none
        max((len(f.params) for f in catalog.functions.values()), default=0),
    )
    wire_fit.check_requests(calls, longest, draft.robot, draft.name, cell.name if cell is not None else "", policy.retries, log, draft.source.at_offset)


def _freeze(draft: ApplicationDraft, checked: list[list[CheckedCall]]) -> tuple[Operation, ...]:
    """The immutable operations, each with its calls, placed at line and column.

    Offsets come in document order (an operation, then its calls), so the lines are counted
    on from one to the next (:meth:`SourceMap.line_cols`) instead of looked up in a table."""
    source = draft.source
    if isinstance(source, ExpandedSource):
        return _freeze_expanded(draft, checked, source)
    file = source.file

    def offsets() -> Iterator[int]:
        for site, calls in zip(draft.operations, checked):
            yield site.at
            for call in calls:
                yield call.site.at

    places = source.line_cols(offsets())
    operations: list[Operation] = []
    for site, calls in zip(draft.operations, checked):
        line, col = next(places)
        frozen: dict[str, Call] = {}
        for call in calls:
            call_line, call_col = next(places)
            call_site = call.site
            frozen[call_site.group] = Call(call_site.group, call_site.function, call.params or (), call_site.implicit, file, call_line, call_col)
        operations.append(Operation(site.id, site.name, line, col, MappingProxyType(frozen), when=site.when, breakpoint=site.breakpoint))
    return tuple(operations)


def _freeze_expanded(draft: ApplicationDraft, checked: list[list[CheckedCall]], source: ExpandedSource) -> tuple[Operation, ...]:
    """:func:`_freeze` of an expanded application: each operation at its line inside its loop (or
    in its called file), with the iteration it was made for."""
    operations: list[Operation] = []
    for site, calls in zip(draft.operations, checked):
        where = source.at_offset(site.at)
        frozen: dict[str, Call] = {}
        for call in calls:
            call_site = call.site
            at = source.at_offset(call_site.at)
            frozen[call_site.group] = Call(call_site.group, call_site.function, call.params or (), call_site.implicit, at.file, at.line, at.col)
        operations.append(Operation(site.id, site.name, where.line, where.col, MappingProxyType(frozen), where.context, site.when, site.breakpoint))
    return tuple(operations)


def load_application(path: Path | str, catalog: Catalog, *, max_bytes: int = DEFAULT_MAX_BYTES) -> Application:
    """The validated application; ApplicationError carrying every diagnostic if it has errors."""
    application, diagnostics = read_application(path, catalog, max_bytes=max_bytes)
    if application is None:
        raise ApplicationError(diagnostics or [Diagnostic(str(path), 1, 1, "invalid application")])
    return application


def validate_application(path: Path | str, catalog: Catalog, *, max_bytes: int = DEFAULT_MAX_BYTES) -> list[Diagnostic]:
    """Every problem (errors and warnings) of the application and its cell; empty when it is clean."""
    return read_application(path, catalog, max_bytes=max_bytes)[1]
