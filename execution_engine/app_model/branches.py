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
    """An ``<if>`` whose outcome the tested function cannot end with is refused at its ``outcome``
    (said once for all the iterations of a loop: the words name the function, not the iteration's id);
    an operation under ``<if>``s that no outcome of the tested function meets together (an ``<if>``
    inside another on the same function, asking another outcome) is refused: it could never run."""
    source = draft.source
    tested = {(condition.operation, condition.group): site for _, condition, site in branches}
    checked: set[tuple[Condition, ...]] = set()
    for operation in draft.operations:
        if operation.when and operation.when not in checked:
            checked.add(operation.when)
            for problem in _never(operation.when, tested, catalog):
                log.append(Diagnostic.at(source.attribute_at(operation.at, "id"), f"operation {operation.id} can never run: {problem}"))
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
            f"<if> tests outcome {condition.outcome!r} of {condition.group}'s {function}, which {function} does not have: {told}"
        )))


def _never(when: tuple[Condition, ...], tested: dict[tuple[str, str], OperationSite], catalog: Catalog) -> list[str]:
    """Why the conditions cannot all hold, one text per tested function they contradict on."""
    problems = []
    for key in dict.fromkeys((c.operation, c.group) for c in when):
        site = tested.get(key)
        spec = catalog.get(site.calls[key[1]].function) if site is not None else None
        if spec is None or not spec.outcomes:
            continue  # reported at its <if>
        asked = [c for c in when if (c.operation, c.group) == key]
        if any(spec.outcome(c.outcome) is None for c in asked):
            continue  # an outcome it does not have: reported at its <if>
        if not any(all(c.met(o.name) for c in asked) for o in spec.outcomes):
            problems.append(f"the <if>s around it ask {' and '.join(c.describe() for c in asked)}, "
                            f"and {spec.name} ends with one of {', '.join(o.name for o in spec.outcomes)}")
    return problems
