"""Static checks of an application's waits: a flag nobody sets, and circular waits (deadlocks).

A ``wait_flag`` ends only when another group's ``set_flag`` of the same name has run, a
synchronised function (master/slave, full body) only when its partners reach it, and in lock-step
(``sync="operation"``) an operation only starts when every group finished the one before.  Flags
are never cleared, so whether an application can get stuck does not depend on timing: each group
is advanced through its calls as far as these rules let it, until nobody can move.  A group left
short of its end is waiting in a cycle (or for a group that is): each stuck call is reported at
its line, naming every flag and line of the cycle.  Interference zones (one call at a time, in
application order) are waits too.  Both modes are checked.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from core_functions.catalog import Catalog
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog
from execution_engine.app_model.reader import ApplicationDraft
from execution_engine.app_model.validation import CheckedCall
from execution_engine.app_model.zones import call_zones

SET, WAIT = "set_flag", "wait_flag"


@dataclass(frozen=True)
class _Step:
    """One call of one group in its order: the operation's index and id, the call, where it is."""

    index: int
    operation: str
    call: CheckedCall
    line: int
    zones: tuple[str, ...] = ()

    @property
    def flag(self) -> str | None:
        params = self.call.params
        return params[0] if self.call.site.function in (SET, WAIT) and params else None


def check_waits(draft: ApplicationDraft, checked: list[list[CheckedCall]], catalog: Catalog, log: DiagnosticLog, cell: object = None) -> None:
    """Report unsatisfiable ``wait_flag`` calls and deadlocks of ``draft`` into ``log`` (zones too, both modes).

    A call in a zone is taken to hold it from its start to its end: at run time it holds it only
    from the motion that enters to the motion that leaves (engine/zones.py), so every wait the
    run can have is one this check has looked at."""
    flags_mode = draft.sync == "flags"
    zoned = bool(getattr(cell, "zones", None))
    if draft.robot is None or not zoned and not any(c.site.function in (SET, WAIT) for calls in checked for c in calls) and not _has_sync(checked, catalog):
        return
    steps: dict[str, list[_Step]] = {g: [] for g in draft.robot.group_names}
    for index, (operation, calls) in enumerate(zip(draft.operations, checked)):
        for call in calls:
            if call.site.group not in steps or (flags_mode and call.site.implicit):
                continue
            synchronised = call.spec is not None and bool(call.spec.sync)  # partners move as one: not gated
            zones = call_zones(cell, call.params) if zoned and call.params and not synchronised else ()
            steps[call.site.group].append(_Step(index, operation.id, call, draft.source.at_offset(call.site.at).line, zones))
    if _unsatisfiable(steps, draft, log):
        return  # a flag nobody sets is the thing to fix; the deadlock it causes would only repeat it
    stuck = _advance(steps, lock_step=not flags_mode)
    for group, position in stuck.items():
        step = steps[group][position]
        chain = "; ".join(_why(g, steps, stuck) for g in _rotated(stuck, group))
        _error(log, draft, step, f"circular wait (deadlock): {chain}")


def _has_sync(checked: list[list[CheckedCall]], catalog: Catalog) -> bool:
    return any(c.spec is not None and c.spec.sync for calls in checked for c in calls)


def _error(log: DiagnosticLog, draft: ApplicationDraft, step: _Step, message: str) -> None:
    if log.full:
        log.count()
        return
    log.append(Diagnostic.at(draft.source.at_offset(step.call.site.at), message))


def _unsatisfiable(steps: dict[str, list[_Step]], draft: ApplicationDraft, log: DiagnosticLog) -> bool:
    setters: dict[str, list[tuple[str, int]]] = {}
    for group, sequence in steps.items():
        for step in sequence:
            if step.call.site.function == SET and step.flag:
                setters.setdefault(step.flag, []).append((group, step.line))
    found = False
    for group, sequence in steps.items():
        for step in sequence:
            if step.call.site.function != WAIT or not step.flag:
                continue
            others = [s for s in setters.get(step.flag, []) if s[0] != group]
            if others:
                continue
            own = [line for g, line in setters.get(step.flag, []) if g == group]
            where = f"only {group} itself sets it (line {', '.join(map(str, own))})" if own else "no set_flag of that name in the application"
            _error(log, draft, step, f"wait_flag({step.flag!r}) of {group} can never end: no other group sets flag {step.flag!r} ({where})")
            found = True
    return found


def _advance(steps: dict[str, list[_Step]], lock_step: bool) -> dict[str, int]:
    """Run every group as far as the waits let it; the groups left short, at the call they wait in."""
    position = dict.fromkeys(steps, 0)
    flags: set[str] = set()
    order = _zone_order(steps)
    heads = dict.fromkeys(order, 0)  # per zone: its first call not yet ended (positions only grow)
    meets = _meetings(steps)

    def zone_free(zone: str, step: _Step) -> bool:
        entries, head = order[zone], heads[zone]
        while head < len(entries) and position[entries[head][2]] > entries[head][3]:
            head += 1
        heads[zone] = head
        _, _, group, k = entries[head]  # the step itself has not ended: head never runs past it
        return steps[group][k] is step

    def blocked(group: str) -> bool:
        step = steps[group][position[group]]
        if lock_step and any(position[g] < len(steps[g]) and steps[g][position[g]].index < step.index for g in steps):
            return True  # the operation before is not over
        if not all(zone_free(zone, step) for zone in step.zones):
            return True  # an earlier call in the zone has not ended
        if step.call.site.function == WAIT and step.flag:
            return step.flag not in flags
        return False

    moved = True
    while moved:
        moved = False
        for group in steps:
            while position[group] < len(steps[group]) and not blocked(group):
                step = steps[group][position[group]]
                partners = _partners(step, meets)
                if partners:
                    if not all(position[p] < len(steps[p]) and steps[p][position[p]].index == step.index for p in partners):
                        break
                    for p in partners:
                        position[p] += 1
                if step.call.site.function == SET and step.flag:
                    flags.add(step.flag)
                position[group] += 1
                moved = True
    return {g: p for g, p in position.items() if p < len(steps[g])}


def _zone_order(steps: dict[str, list[_Step]]) -> dict[str, list[tuple[int, int, str, int]]]:
    """Each zone's calls in application order: (operation index, group rank, group, position in its group)."""
    order: dict[str, list[tuple[int, int, str, int]]] = {}
    for rank, (group, sequence) in enumerate(steps.items()):
        for k, step in enumerate(sequence):
            for zone in step.zones:
                order.setdefault(zone, []).append((step.index, rank, group, k))
    for entries in order.values():
        entries.sort()
    return order


def _before_in_zone(zone: str, step: _Step, order: dict, steps: dict[str, list[_Step]], position: dict[str, int]) -> tuple[str, int] | None:
    """The earlier call in ``zone`` that has not ended yet (group, line), or None."""
    for index, _, group, k in order[zone]:
        if group == step.call.site.group and steps[group][k] is step:
            return None
        if position[group] <= k:
            return group, steps[group][k].line
    return None


def _meetings(steps: dict[str, list[_Step]]) -> dict[tuple[int, object], list[str]]:
    """For each operation and kind of synchronisation, the groups whose calls meet there (worked out once: a
    scan of every group's calls per synchronised call made the check quadratic in the application's length)."""
    meets: dict[tuple[int, object], list[str]] = {}
    for group, sequence in steps.items():
        for step in sequence:
            spec = step.call.spec
            if spec is not None and spec.sync:
                groups = meets.setdefault((step.index, spec.sync), [])
                if group not in groups:
                    groups.append(group)
    return meets


def _partners(step: _Step, meets: dict[tuple[int, object], list[str]]) -> list[str]:
    """The other groups a synchronised call meets in its operation (none for any other call)."""
    spec = step.call.spec
    if spec is None or not spec.sync:
        return []
    return [g for g in meets[(step.index, spec.sync)] if g != step.call.site.group]


def _rotated(stuck: dict[str, int], first: str) -> Iterator[str]:
    groups = list(stuck)
    k = groups.index(first)
    yield from groups[k:] + groups[:k]


def _why(group: str, steps: dict[str, list[_Step]], stuck: dict[str, int]) -> str:
    """What ``group`` waits for at the call it is stuck in, and who would end the wait."""
    step = steps[group][stuck[group]]
    here = f"{group} at line {step.line} ({step.call.site.function}"
    position = {g: stuck.get(g, len(s)) for g, s in steps.items()}
    order = _zone_order(steps)
    for zone in step.zones:
        first = _before_in_zone(zone, step, order, steps, position)
        if first is not None:
            return f"{here}) waits for zone {zone!r}, where {first[0]} works first, at line {first[1]}"
    if step.call.site.function == WAIT and step.flag:
        setters = [
            f"{g} sets only at line {s.line}"
            for g, sequence in steps.items() if g != group and g in stuck
            for s in sequence[stuck[g]:] if s.call.site.function == SET and s.flag == step.flag
        ]
        return f"{here}) waits for flag {step.flag!r}, which " + (" and ".join(setters) or "no group still running sets")
    if step.call.spec is not None and step.call.spec.sync:
        return f"{here}) waits for its partners in operation {step.operation}"
    return f"{here}, operation {step.operation}) waits for the operation before it to end"
