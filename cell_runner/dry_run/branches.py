"""Every side of every ``<if>`` dry-run: the outcomes the dry run assumes, one pass per set of them.

The simulator decides an outcome one way (its cameras find every hole of a nominal cell), so a
dry run that only followed the simulator would never check the ``not_found`` side -- and a
collision or an unreachable target there would first be met by the robot.  So the dry run
*assumes* the outcomes instead: each pass fixes an outcome for every function an ``<if>`` tests,
keeps the operations whose conditions those outcomes meet (and drops their conditions, so the
engine runs exactly them), and runs as any dry run does -- a tested function whose simulated
camera does not find its feature ends with its outcome there too, not with a finding.  The passes are chosen so that every
distinct set of conditions some operation is under is met in at least one pass: greedily, each
pass taking every side not yet covered that agrees with what the pass already assumes; a tested
function's first outcome (the one it ends with when it succeeds) where nothing else is needed.
The first pass is the one the simulator would take by itself, all successes; it gives the
prediction (cycle time, timeline).

A pass can assume what the simulated cell contradicts (``found`` for a hole the cell does not
have): the operations of that side, which locate the hole again, then meet the same vision fault.
That fault follows from the assumption, so the recorder holds it back (:meth:`Recorder.defer`) and
excuses it -- same kind, same target, in an operation whose conditions name that function -- with a
note; the vision answers the nominal pose and every motion of the side is checked from there.
"""
from __future__ import annotations

from dataclasses import replace

from core_functions.catalog import Catalog
from execution_engine.app_model.model import Application, Condition

#: The outcome assumed for each tested function, by (operation, group).
Assumption = dict[tuple[str, str], str]


def has_branches(app: Application) -> bool:
    return any(operation.when for operation in app.operations)


def _outcomes(app: Application, catalog: Catalog, key: tuple[str, str]) -> tuple[str, ...]:
    operation, group = key
    spec = catalog.get(app.operation(operation).calls[group].function)  # a tested operation: validated to exist
    return tuple(o.name for o in spec.outcomes) if spec is not None else ()


def _fits(assumed: Assumption, conditions: tuple[Condition, ...], app: Application, catalog: Catalog) -> Assumption | None:
    """``assumed`` with what ``conditions`` need added, or None when they contradict it."""
    out = dict(assumed)
    for condition in conditions:
        key = (condition.operation, condition.group)
        if key in out:
            if not condition.met(out[key]):
                return None
            continue
        choices = [o for o in _outcomes(app, catalog, key) if condition.met(o)]
        if not choices:
            return None  # the validation refuses such a condition; nothing to run under it
        out[key] = choices[0]
    return out


def assumptions(app: Application, catalog: Catalog) -> list[Assumption]:
    """The passes: each an outcome for every tested function; together they meet every operation's conditions."""
    tested = sorted(app.tested())
    sides = list(dict.fromkeys(operation.when for operation in app.operations if operation.when))
    passes: list[Assumption] = []
    uncovered = sides
    first = True
    while uncovered:
        assumed: Assumption = {}
        left = []
        for side in uncovered:
            if first and any(not c.holds for c in side):
                left.append(side)  # the first pass: the successes alone
                continue
            fitted = _fits(assumed, side, app, catalog)
            if fitted is None:
                left.append(side)
            else:
                assumed = fitted
        if len(left) == len(uncovered) and not first:
            break  # nothing could be met (only a condition the validation refuses)
        for key in tested:
            if key not in assumed:
                names = _outcomes(app, catalog, key)
                if names:
                    assumed[key] = names[0]
        passes.append(assumed)
        uncovered, first = left, False
    return passes or [{}]


def resolved(app: Application, assumed: Assumption) -> Application:
    """``app`` as it runs when the tested functions end as ``assumed``: the operations whose
    conditions that meets, without their conditions."""
    operations = tuple(
        replace(operation, when=()) for operation in app.operations
        if all(c.met(assumed.get((c.operation, c.group))) for c in operation.when)
    )
    return replace(app, operations=operations, resolved_tests=app.tested())


def outcome_faults(app: Application, catalog: Catalog) -> dict[tuple[str, str], frozenset[str]]:
    """The fault kinds that end each tested function with an outcome (vision: not_found), by (operation, group)."""
    out: dict[tuple[str, str], frozenset[str]] = {}
    by_id = {operation.id: operation for operation in app.operations}
    for operation, group in app.tested():
        if operation not in by_id or group not in by_id[operation].calls:
            continue  # left out by this pass
        spec = catalog.get(by_id[operation].calls[group].function)
        kinds = frozenset(o.fault for o in spec.outcomes if o.fault) if spec is not None else frozenset()
        if kinds:
            out[(operation, group)] = kinds
    return out


def fault_outcomes(app: Application, catalog: Catalog) -> dict[tuple[str, str], dict[str, str]]:
    """The outcome each of a tested function's outcome faults stands for (vision: not_found), by (operation, group):
    how a pass tells that the simulated cell ended the function otherwise than the pass assumed."""
    out: dict[tuple[str, str], dict[str, str]] = {}
    by_id = {operation.id: operation for operation in app.operations}
    for operation, group in app.tested():
        if operation in by_id and group in by_id[operation].calls:
            spec = catalog.get(by_id[operation].calls[group].function)
            if spec is not None:
                out[(operation, group)] = {o.fault: o.name for o in spec.outcomes if o.fault}
    return out


def sides(app: Application) -> dict[str, frozenset[tuple[str, str]]]:
    """The tested functions (operation, group) whose outcome each operation's ``<if>``/``<else>`` sides depend on, by
    operation id (of ``app`` before :func:`resolved` drops the conditions): the operations a pass runs *because*
    of what it assumed of that function."""
    return {operation.id: frozenset((c.operation, c.group) for c in operation.when) for operation in app.operations if operation.when}


def describe(assumed: Assumption) -> str:
    """``look_drill_1 left_arm found, look_drill_2 left_arm not_found``: the words of the report."""
    return ", ".join(f"{operation} {group} {outcome}" for (operation, group), outcome in assumed.items()) or "nothing"
