"""The catalog's check of every ``<if>``: the outcome it tests is one the tested function has.

Run after the expansion (which checked that the tested operation comes before the ``<if>`` and
gives the group a function) and after the functions themselves were checked, so an unknown
function is reported once, where it is called, not again at every ``<if>`` that tests it.
"""
from __future__ import annotations

from core_functions.catalog import Catalog
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog
from execution_engine.app_model.model import Condition
from execution_engine.app_model.reader import ApplicationDraft, OperationSite


def check_branches(branches: list[tuple[int, Condition, OperationSite]], draft: ApplicationDraft, catalog: Catalog, log: DiagnosticLog) -> None:
    """An ``<if>`` whose outcome the tested function cannot end with is refused at its ``outcome``."""
    source = draft.source
    for at, condition, tested in branches:
        function = tested.calls[condition.group].function
        spec = catalog.get(function)
        if spec is None:
            continue  # reported at the call
        if spec.outcome(condition.outcome) is not None:
            continue
        where = source.attribute_offset(at, "outcome")
        has = ", ".join(o.name for o in spec.outcomes)
        told = f"its outcomes: {has}" if has else "it has no named outcomes (it succeeds or fails; `functions` lists the outcomes of each function)"
        log.append(Diagnostic.at(source.at_offset(where), (
            f"<if> tests outcome {condition.outcome!r} of {function} ({condition.group} in operation {condition.operation}), "
            f"which {function} does not have: {told}"
        )))
