"""Semantic checks of an application against the robot, the function catalog and the cell model.

What the schema cannot see: whether each function exists and fits its group, whether its params
parse (types, units, ranges, frames and elements of the cell), whether synchronised functions have
their partners in the same operation, and -- after Verl et al.'s plausibility check when processes
are concatenated -- whether each hand holds what a function needs, given what the functions
before it left there.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from core_functions.catalog import BindContext, Catalog, FunctionSpec, Hold, ParamError, ParamType
from core_functions.robots import RobotModel
from execution_engine.app_model.cell_model import Cell
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, Location
from execution_engine.app_model.model import WAIT, ErrorAction, ErrorPolicy
from execution_engine.app_model.reader import ApplicationDraft, CallSite, OperationSite, PolicySite

# Params whose check needs the cell model; not checked while the cell itself has errors.
_REFERENCE_TYPES = frozenset({ParamType.FRAME, ParamType.FRAMES, ParamType.ELEMENT, ParamType.TARGET, ParamType.JOINT_POSE})
_ACTIONS: tuple[ErrorAction, ...] = ("abort", "safe_pose", "alarm")
#: Calls whose problems may carry a 'did you mean' (an unknown function, frame); later ones are
#: reported without, so a file of 100,000 unknown names costs 100,000 look-ups, not searches.
MAX_SUGGESTIONS = 100


@dataclass(slots=True)
class CheckedCall:
    """A call after checking: its catalog entry (None: unknown or built-in wait) and normalised params."""

    site: CallSite
    spec: FunctionSpec | None
    params: tuple[str, ...] | None  # None: the call has errors


@dataclass
class _HoldState:
    hold: Hold
    function: str = ""
    operation: str = ""
    at: int = 0  # offset of the function that set the hold
    #: After an <if> whose sides leave the hand differently: what each side left, with the side's condition.
    sides: tuple[tuple[str, _HoldState], ...] = ()


class ApplicationChecker:
    def __init__(
        self, draft: ApplicationDraft, robot: RobotModel, catalog: Catalog, cell: Cell | None, cell_broken: bool,
        log: DiagnosticLog | None = None,
    ) -> None:
        self.draft = draft
        self.robot = robot
        self.catalog = catalog
        self.cell = cell
        self.cell_broken = cell_broken
        self.diagnostics = log if log is not None else DiagnosticLog()
        self.suggestions_left = MAX_SUGGESTIONS
        self._contexts = {g: BindContext(robot, g, cell) for g in robot.group_names}
        self._plain_contexts = {g: BindContext(robot, g, cell, suggest=False) for g in robot.group_names}
        self._checked: dict[tuple[str, str, tuple[str, ...]], list[ParamError]] = {}
        # (function, group, values) -> its catalog entry and complete params, for a call found clean
        # (params, joint poses): a generated file repeats a handful of calls thousands of times.
        self._clean: dict[tuple[str, str, tuple[str, ...]], tuple[FunctionSpec, tuple[str, ...]]] = {}
        self._groups = robot.group_names
        self._joint_pose_functions = {
            f.name for f in catalog.functions.values() if any(p.type is ParamType.JOINT_POSE for p in f.params)
        }
        wait = catalog.get(WAIT)
        self._wait_defaults = tuple(p.default or "" for p in wait.params) if wait and wait.required_count == 0 else ()

    def error(self, where: Location, message: str) -> None:
        self.diagnostics.append(Diagnostic.at(where, message))

    def error_at(self, offset: int, message: str) -> None:
        if self.diagnostics.full:
            self.diagnostics.count()  # beyond the report: no need to find the line
            return
        self.error(self.draft.source.at_offset(offset), message)

    def error_at_attribute(self, tag_offset: int, name: str, message: str) -> None:
        if self.diagnostics.full:
            self.diagnostics.count()
            return
        self.error(self.attribute(tag_offset, name), message)

    def attribute(self, tag_offset: int, name: str) -> Location:
        return self.draft.source.attribute_at(tag_offset, name)

    def suggesting(self) -> bool:
        """Whether the next call's problems may still carry 'did you mean' (and spends one)."""
        if self.suggestions_left <= 0 or self.diagnostics.full:
            return False
        self.suggestions_left -= 1
        return True

    # ------------------------------------------------------------------ the whole file
    def check(self) -> list[list[CheckedCall]]:
        """Each operation's calls, one per robot group, in the robot's group order."""
        checked: list[list[CheckedCall]] = []
        groups, check_call, clean = self._groups, self.check_call, self._clean
        # synchronised functions, by name: an operation without any skips their checks
        synchronised = frozenset(name for name, f in self.catalog.functions.items() if f.sync in ("full_body", "master_slave"))
        for operation in self.draft.operations:
            calls: list[CheckedCall] = []
            by_group = operation.calls
            for group in groups:
                call = by_group.get(group)
                if call is None:
                    calls.append(self.check_call(self.call_for(operation, group)))
                    continue
                known = clean.get((call.function, group, call.values)) if call.names is None else None
                calls.append(CheckedCall(call, *known) if known is not None else check_call(call))
            if not synchronised.isdisjoint([call.function for call in by_group.values()]):
                self.check_full_body(operation, calls)
                self.check_master_slave(operation, calls)
            checked.append(calls)
        self.check_holds(self.draft.operations, checked)
        return checked

    def call_for(self, operation: OperationSite, group: str) -> CallSite:
        return operation.calls.get(group) or CallSite(group=group, function=WAIT, values=(), param_at=(), at=operation.at, implicit=True)

    # ------------------------------------------------------------------ one call
    def check_call(self, call: CallSite) -> CheckedCall:
        if call.implicit:
            return CheckedCall(call, self.catalog.get(WAIT), self._wait_defaults)
        spec = self.catalog.get(call.function)
        if spec is None:
            if call.function == WAIT:  # built in when the catalog has no wait of its own
                if call.values:
                    self.error_at(call.param_at[0], "wait takes no params")
                    return CheckedCall(call, None, None)
                return CheckedCall(call, None, ())
            hint = self.catalog.suggest(call.function) if self.suggesting() else ""
            self.error_at_attribute(call.at, "name", f"unknown function {call.function!r}{hint}")
            return CheckedCall(call, None, None)
        texts = call.values
        ok = self.check_param_names(call, spec)
        key = (spec.name, call.group, texts)
        problems = self._checked.get(key)
        if problems is None:
            problems = spec.check(texts, self._plain_contexts[call.group])
            if problems and self.suggesting():  # again, with the 'did you mean' searches
                problems = spec.check(texts, self._contexts[call.group])
            self._checked[key] = problems
        for problem in problems:
            if problem.index is None:
                self.error_at(call.at, problem.message)
                ok = False
            elif self.cell_broken and spec.params[problem.index].type in _REFERENCE_TYPES:
                continue  # the cell's own errors are reported; fix those first
            else:
                self.error_at_attribute(call.param_at[problem.index], "value", problem.message)
                ok = False
        ok = self.check_joint_pose_groups(call, spec, texts) and ok
        if not ok or len(texts) > len(spec.params):
            return CheckedCall(call, spec, None)
        defaults = tuple(p.default or "" for p in spec.params[len(texts):])
        if not problems and call.function == spec.name:
            self._clean[(call.function, call.group, texts)] = (spec, texts + defaults)
        return CheckedCall(call, spec, texts + defaults)

    def check_param_names(self, call: CallSite, spec: FunctionSpec) -> bool:
        """A ``name`` on a param must be the catalog's name at that position: params bind by position."""
        ok = True
        if call.names is None:
            return ok
        names = [p.name for p in spec.params]
        for index, (name, at) in enumerate(zip(call.names, call.param_at)):
            if name is None or (index < len(names) and names[index] == name):
                continue
            if name not in names:
                self.error_at_attribute(at, "name", f"{spec.name} has no param named {name!r}; its params are {spec.signature()}")
                ok = False
            elif index < len(names):
                self.error_at_attribute(at, "name", (
                    f"param {index + 1} is named {name!r}, but {spec.name} takes {name!r} as param "
                    f"{names.index(name) + 1} and {names[index]!r} here: params bind by position ({spec.signature()})"
                ))
                ok = False
        return ok

    def check_joint_pose_groups(self, call: CallSite, spec: FunctionSpec, texts: Sequence[str]) -> bool:
        """A cell joint pose made for one group cannot be used by another."""
        if self.cell is None or spec.name not in self._joint_pose_functions:
            return True
        ok = True
        for index, (param, text) in enumerate(zip(spec.params, texts)):
            name = text.strip()
            if param.type is not ParamType.JOINT_POSE or name in self.robot.poses or not self.cell.has_joint_pose(name):
                continue
            pose_group = self.cell.joint_pose(name).group
            if pose_group is not None and pose_group != call.group:
                self.error_at_attribute(
                    call.param_at[index], "value",
                    f"param {index + 1} ({param.name}) of {spec.name}: joint pose {name!r} is for {pose_group}, not {call.group}",
                )
                ok = False
        return ok

    # ------------------------------------------------------------------ synchronised functions
    def check_full_body(self, operation: OperationSite, calls: list[CheckedCall]) -> None:
        """A full-body function runs in every arm with the same params; torso_head joins in or waits."""
        leaders = [c for c in calls if c.spec is not None and c.spec.sync == "full_body" and not c.site.implicit]
        if not leaders:
            return
        leader = min(leaders, key=lambda c: c.site.at)
        if leader.params is None:
            return
        wanted = tuple(t.strip() for t in leader.params)
        arms = set(self.robot.arm_groups)
        for call in calls:
            if call is leader:
                continue
            same = call.site.function == leader.site.function and call.params is not None and tuple(t.strip() for t in call.params) == wanted
            if same or (call.site.group not in arms and call.site.function == WAIT):
                continue
            if call.params is None and call.site.function == leader.site.function:
                continue  # its own errors are reported
            need = "call it too with the same params" + ("" if call.site.group in arms else ", or wait")
            shown = f"{leader.site.function}({', '.join(wanted)})"
            if call.site.implicit:
                self.error_at(leader.site.at, f"{shown} on {leader.site.group} is a full-body function: {call.site.group} must {need}, but it is left out of operation {operation.id}")
            else:
                self.error_at(call.site.at, f"{shown} on {leader.site.group} is a full-body function: {call.site.group} must {need}, but calls {self.describe(call)}")

    def check_master_slave(self, operation: OperationSite, calls: list[CheckedCall]) -> None:
        """A master and a slave function name each other's group in the same operation."""
        by_group = {c.site.group: c for c in calls}
        for call in calls:
            partner_name = self.partner(call)
            if partner_name is None or partner_name not in by_group:
                continue
            partner = by_group[partner_name]
            role = self.role(call)
            if partner.spec is None or partner.spec.sync != "master_slave":
                if partner.spec is None and partner.params is None and not partner.site.implicit and partner.site.function != WAIT:
                    continue  # unknown partner function: reported already
                self.error_at(call.site.at, (
                    f"{call.site.function} on {call.site.group} names {partner_name} as its {self.opposite(role)}, but {partner_name} "
                    f"{'is left out of' if partner.site.implicit else 'calls ' + self.describe(partner) + ' in'} operation {operation.id}; "
                    f"it must call the matching master/slave function naming {call.site.group}"
                ))
                continue
            back = self.partner(partner)
            if back is not None and back != call.site.group:
                self.error_at(call.site.at, f"{call.site.function} on {call.site.group} names {partner_name}, but {partner_name}'s {partner.site.function} names {back}: they must name each other")
            elif back is not None and role is not None and role == self.role(partner) and call.site.at < partner.site.at:
                self.error_at(call.site.at, f"{call.site.group} and {partner_name} are both {role}s in operation {operation.id}: one arm leads (master), the other follows (slave)")

    def partner(self, call: CheckedCall) -> str | None:
        if call.spec is None or call.spec.sync != "master_slave" or call.params is None:
            return None
        for param, text in zip(call.spec.params, call.params):
            if param.type is ParamType.GROUP:
                return text.strip()
        return None

    @staticmethod
    def role(call: CheckedCall) -> str | None:
        """``master`` when the group param names the slave, ``slave`` when it names the master."""
        assert call.spec is not None
        names = {p.name for p in call.spec.params if p.type is ParamType.GROUP}
        return "master" if "slave" in names else "slave" if "master" in names else None

    @staticmethod
    def opposite(role: str | None) -> str:
        return {"master": "slave", "slave": "master"}.get(role or "", "partner")

    @staticmethod
    def describe(call: CheckedCall) -> str:
        params = call.params if call.params is not None else call.site.values
        return f"{call.site.function}({', '.join(params)})"

    # ------------------------------------------------------------------ plausibility
    def check_holds(self, operations: Sequence[OperationSite], checked: Sequence[Sequence[CheckedCall]]) -> None:
        """Track what each hand holds from operation to operation (Verl et al. 2008, section 6.2).  Both
        sides of an <if> start from what the hands held before it; after it, a hand that holds one thing
        after one side and another after the other is not known (what follows is not checked against it)."""
        self._holds(list(zip(operations, checked)), 0, {g: _HoldState(Hold.NOTHING) for g in self.robot.group_names})

    def _holds(self, pairs: list[tuple[OperationSite, Sequence[CheckedCall]]], depth: int, state: dict[str, _HoldState]) -> dict[str, _HoldState]:
        """The hands after ``pairs`` (each under ``depth`` conditions already taken), from ``state``."""
        i = 0
        while i < len(pairs):
            operation, calls = pairs[i]
            if len(operation.when) <= depth:
                self._hold_calls(operation, calls, state)
                i += 1
                continue
            head = operation.when[depth]
            taken: list[tuple[OperationSite, Sequence[CheckedCall]]] = []
            other: list[tuple[OperationSite, Sequence[CheckedCall]]] = []
            while i < len(pairs):  # the <if>'s operations, then its <else>'s
                when = pairs[i][0].when
                if len(when) <= depth or (when[depth].operation, when[depth].group, when[depth].outcome) != (head.operation, head.group, head.outcome):
                    break
                if when[depth].holds and other:
                    break  # another <if> on the same outcome, right after this one's <else>
                (taken if when[depth].holds else other).append(pairs[i])
                i += 1
            after = self._holds(taken, depth + 1, dict(state))
            otherwise = self._holds(other, depth + 1, dict(state))
            negated = replace(head, holds=not head.holds)
            state = {g: after[g] if after[g] == otherwise[g] else _joined(((head.describe(), after[g]), (negated.describe(), otherwise[g])))
                     for g in state}
        return state

    def _hold_calls(self, operation: OperationSite, calls: Sequence[CheckedCall], state: dict[str, _HoldState]) -> None:
        for call in calls:
            group = call.site.group
            spec = call.spec
            if spec is None:
                if call.site.function != WAIT:
                    state[group] = _HoldState(Hold.UNKNOWN)  # unknown function: anything may have happened
                continue
            current = state[group]
            for side, held in current.sides or (("", current),):  # after an <if>: what each of its sides left
                if spec.requires is not None and held.hold is not Hold.UNKNOWN and spec.requires is not held.hold:
                    line = self.draft.source.at_offset(held.at).line
                    self.error_at(call.site.at, self.hold_message(spec, group, held, line) + (f" (on the side of the <if> where {side})" if side else ""))
                    break
            if spec.leaves is not None:
                state[group] = _HoldState(spec.leaves, spec.name, operation.id, call.site.at)

    @staticmethod
    def hold_message(spec: FunctionSpec, group: str, current: _HoldState, line: int) -> str:
        since = f"operation {current.operation} (line {line}), where {current.function} left it empty" if current.function else "the start of the application"
        if spec.requires is Hold.PART:
            return f"{spec.name} needs the {group} to hold a part, but nothing was picked since {since}"
        if current.function:
            return f"{spec.name} needs the {group}'s hand to be empty, but it still holds what {current.function} took in operation {current.operation} (line {line})"
        return f"{spec.name} needs the {group}'s hand to be {spec.requires.value if spec.requires else 'free'}, but it holds {current.hold.value}"

    # ------------------------------------------------------------------ error policy
    def check_policy(self, policy: PolicySite | None) -> ErrorPolicy:
        default_pose = "initial" if "initial" in self.robot.poses else None
        if policy is None:
            return ErrorPolicy(safe_pose=default_pose)
        action: ErrorAction = next((a for a in _ACTIONS if a == policy.action), "abort")
        safe_pose = policy.safe_pose
        if safe_pose is None and action == "safe_pose" and default_pose is None:
            self.error_at(policy.at, (
                f"error_policy action safe_pose needs a safe_pose: {self.robot.name} has no 'initial' pose "
                f"(its poses: {', '.join(sorted(self.robot.poses)) or 'none'}; or a <joint_pose> of the cell)"
            ))
        if safe_pose is not None and safe_pose not in self.robot.poses and not self.cell_broken:
            if self.cell is None or not self.cell.has_joint_pose(safe_pose):
                cell_poses = sorted(self.cell.joint_poses) if self.cell is not None else []
                self.error_at_attribute(policy.at, "safe_pose", (
                    f"unknown safe_pose {safe_pose!r} (robot poses: {', '.join(sorted(self.robot.poses)) or 'none'}; "
                    f"cell joint poses: {', '.join(cell_poses) or 'none'})"
                ))
        return ErrorPolicy(
            retries=policy.retries or 0,
            action=action,
            safe_pose=safe_pose or default_pose,
            alarm_timeout=ErrorPolicy.alarm_timeout if policy.alarm_timeout is None else policy.alarm_timeout,
            safe_speed=ErrorPolicy.safe_speed if policy.safe_speed is None else policy.safe_speed,
            retreat=ErrorPolicy.retreat if policy.retreat is None else policy.retreat,
        )


def _joined(sides: tuple[tuple[str, _HoldState], ...]) -> _HoldState:
    """A hand after an <if> whose sides left it differently: each side kept (nested sides flattened)."""
    flat = tuple((f"{label} and {inner}" if inner else label, held) for label, state in sides for inner, held in (state.sides or (("", state),)))
    return _HoldState(Hold.UNKNOWN, sides=flat)
