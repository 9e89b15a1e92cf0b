"""Read an application document into drafts that remember where everything was written.

The reader runs after the schema check whatever its outcome, so one run reports structural and
semantic problems together.  It therefore never trusts the shape of the document: what it cannot
interpret it skips silently (the schema has said why), and it reports only what a schema cannot
know -- the robot, the robot's groups, repeated ids and groups, the cell file.

It walks the whole tree top-down, visiting every element once in document order, so positions
come from :class:`DocumentWalk` as plain offsets; drafts keep no lxml elements, which lets the
tree go as soon as reading is done.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

from lxml import etree

from core_functions import limits
from core_functions.printable import printable, unsafe_character
from core_functions.cell_robots import CELL_ROBOT, cell_robot_model
from core_functions.robots import RobotModel, find_robot
from execution_engine.app_model.cell import read_cell_log
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, Location
from execution_engine.app_model.expanded_source import ExpandedSource
from execution_engine.app_model.model import Condition
from execution_engine.app_model.positions import DocumentWalk, SourceMap
from execution_engine.app_model.safe_xml import XmlDocument

GROUP_TAGS = frozenset({"left_arm", "right_arm", "torso_head", "arm"})  # as in application.xsd
#: The elements that hold or bring in operations (as in application.xsd), expanded by app_model.expand.
STEP_TAGS = frozenset({"for_each", "repeat", "call", "if", "else"})
BREAK_TRUE = ("true",)  # break="true"; the schema takes only true or false
#: The variable a loop counts its iterations in (from 1) when it does not name one.
INDEX = "index"


@dataclass(slots=True)
class CallSite:
    """One group's ``<function>`` (``at``: its offset), or the implicit wait of a group left out.

    The params as written, as parallel tuples -- a 10^5-call file has 10^5 of these, and tuples
    cost a fraction of an object per param: ``values``, the offsets of their start tags
    (``param_at``), and their ``name`` attributes (``names``: None when no param has one)."""

    group: str
    function: str
    values: tuple[str, ...]
    param_at: tuple[int, ...]
    at: int
    names: tuple[str | None, ...] | None = None
    implicit: bool = False


@dataclass(slots=True)
class OperationSite:
    id: str
    name: str | None
    at: int
    calls: dict[str, CallSite] = field(default_factory=dict)
    when: tuple[Condition, ...] = ()  # the <if>/<else> around it, once expanded (app_model.expand)
    breakpoint: bool = False  # break="true": the run pauses before it (engine/breakpoints.py)


@dataclass(slots=True)
class LoopSite:
    """A ``<for_each>`` (``values``: its ``in`` as written) or a ``<repeat>`` (``count``), with the
    steps inside.  ``var``: the variable each value (for_each) or each count (repeat) is bound
    to; ``index``: the for_each's position variable (``index`` unless named); ``named``: the
    variables the file names itself, which a loop inside may not take again."""

    kind: str
    at: int
    var: str
    index: str | None = None
    values: str = ""
    count: int = 0
    named: tuple[str, ...] = ()
    body: list[Step] = field(default_factory=list)


@dataclass(slots=True)
class CallBlockSite:
    """A ``<call application=...>`` and its ``<param name value>`` (``params``: name, value, offset)."""

    at: int
    application: str
    params: list[tuple[str, str, int]] = field(default_factory=list)


@dataclass(slots=True)
class IfSite:
    """An ``<if group operation outcome>`` and the ``<else>`` right after it (``else_at``: None when
    there is none): the steps of ``body`` run when ``group``'s function in ``operation`` (its id as
    written, loop variables not yet substituted) ended with ``outcome``, those of ``orelse`` otherwise."""

    at: int
    group: str
    operation: str
    outcome: str
    body: list[Step] = field(default_factory=list)
    else_at: int | None = None
    orelse: list[Step] = field(default_factory=list)


@dataclass(slots=True)
class ElseSite:
    """An ``<else>`` as read, before it is joined to the ``<if>`` it follows."""

    at: int
    body: list[Step] = field(default_factory=list)


#: One step of an application's body, in document order: loops, calls and branches are expanded later.
Step = Union[OperationSite, LoopSite, CallBlockSite, IfSite]


@dataclass(slots=True)
class PolicySite:
    """``<error_policy>`` as written; values the schema rejected are left at None."""

    at: int
    retries: int | None = None
    action: str | None = None
    safe_pose: str | None = None
    alarm_timeout: float | None = None
    safe_speed: float | None = None
    retreat: float | None = None


@dataclass
class ApplicationDraft:
    source: SourceMap | ExpandedSource  # ExpandedSource once loops and calls are expanded (app_model.expand)
    name: str
    robot: RobotModel | None
    cell_path: Path | None = None
    cell_display: str | None = None
    cell_where: Location | None = None
    description: str = ""
    version: str | None = None
    sync: str = "operation"  # how the groups keep together: "operation" (lock-step) or "flags"
    policy: PolicySite | None = None
    operations: list[OperationSite] = field(default_factory=list)
    #: Every step in document order, loops and calls included (``operations`` then holds only the
    #: top-level operations until app_model.expand replaces them with the expansion).
    body: list[Step] = field(default_factory=list)
    has_steps: bool = False  # a loop or a call is written: the body must be expanded


class ApplicationReader:
    def __init__(self, doc: XmlDocument, log: DiagnosticLog | None = None) -> None:
        self.doc = doc
        self.source = doc.source
        self.walk = DocumentWalk(doc.source)
        self.diagnostics = log if log is not None else DiagnosticLog()
        self.groups: frozenset[str] = GROUP_TAGS
        #: One string for each distinct param value and function name: a large file repeats a
        #: few hundred of them (frames, speeds, modes) tens of thousands of times.
        self.shared: dict[str, str] = {}

    def error(self, at: int, message: str) -> None:
        if self.diagnostics.full:
            self.diagnostics.count()  # beyond the report: counted, not located
            return
        self.diagnostics.append(Diagnostic.at(self.source.at_offset(at), message))

    def read(self) -> ApplicationDraft:
        root = self.doc.root
        root_at = self.walk.visit(root)
        draft = ApplicationDraft(source=self.source, name=root.get("name", ""), robot=self.read_robot(root, root_at))
        draft.version = root.get("version")
        draft.sync = root.get("sync", "operation") if root.get("sync") in ("operation", "flags") else "operation"
        self.read_cell_reference(root, root_at, draft)
        if draft.robot is not None:
            self.groups = frozenset(draft.robot.group_names)
        ids: dict[str, OperationSite] = {}
        read_operation = self.read_valid_operation if self.doc.valid_against is not None else self.read_operation
        for child in root:
            if not isinstance(child.tag, str):  # a comment or processing instruction
                continue
            at = self.walk.visit(child)
            if child.tag == "operation":
                operation = read_operation(child, at, draft.robot)
                if operation is None:
                    continue
                first = ids.get(operation.id)
                if first is not None:
                    line = self.source.at_offset(first.at).line
                    self.error(self.source.attribute_offset(at, "id"), f"operation id {operation.id!r} is used twice (first on line {line})")
                else:
                    ids[operation.id] = operation
                draft.operations.append(operation)
                draft.body.append(operation)
                continue
            if child.tag in STEP_TAGS:
                step = self.read_step(child, at, draft.robot)
                if step is not None:
                    self.add_step(draft.body, step)
                    draft.has_steps = True
                continue
            if child.tag == "description":
                draft.description = (child.text or "").strip()
            elif child.tag == "error_policy" and draft.policy is None:
                draft.policy = self.read_policy(child, at)
            self.walk.skip(child)
        return draft

    def add_step(self, body: list[Step], step: Step | ElseSite) -> None:
        """Append a step read; an ``<else>`` joins the ``<if>`` right before it (anywhere else it is
        refused at its line: what it would be the other side of is not written)."""
        if not isinstance(step, ElseSite):
            body.append(step)
            return
        last = body[-1] if body else None
        if isinstance(last, IfSite) and last.else_at is None:
            last.else_at, last.orelse = step.at, step.body
        elif isinstance(last, IfSite):
            self.error(step.at, "a second <else> for the same <if>: one <else> holds everything run otherwise")
        else:
            self.error(step.at, "<else> must come right after an <if> (the operations run when the <if>'s outcome is not met)")

    def read_step(self, element: etree._Element, at: int, robot: RobotModel | None) -> LoopSite | CallBlockSite | IfSite | ElseSite | None:
        """A loop with the steps inside it, or a call with its params (None: the schema says what
        is wrong with it).  Every element below is visited, in document order."""
        if element.tag == "call":
            call = CallBlockSite(at, (element.get("application") or "").strip())
            for child in element:
                if not isinstance(child.tag, str):
                    continue
                child_at = self.walk.visit(child)
                self.walk.skip(child)
                name, value = child.get("name"), child.get("value")
                if child.tag == "param" and name is not None and value is not None:
                    call.params.append((name.strip(), value, child_at))
            return call if call.application else None
        block: LoopSite | IfSite | ElseSite | None
        if element.tag == "if":
            group, operation, outcome = ((element.get(a) or "").strip() for a in ("group", "operation", "outcome"))
            block = IfSite(at, group, operation, outcome) if group and operation and outcome else None
        elif element.tag == "else":
            block = ElseSite(at)
        else:
            block = self.read_loop_head(element, at)
        body: list[Step] = block.body if block is not None else []
        read_operation = self.read_valid_operation if self.doc.valid_against is not None else self.read_operation
        for child in element:
            if not isinstance(child.tag, str):
                continue
            child_at = self.walk.visit(child)
            if child.tag == "operation":
                operation_site = read_operation(child, child_at, robot)
                if operation_site is not None:
                    body.append(operation_site)
            elif child.tag in STEP_TAGS:
                step = self.read_step(child, child_at, robot)
                if step is not None:
                    self.add_step(body, step)
            else:
                self.walk.skip(child)  # the schema reports it
        return block

    @staticmethod
    def read_loop_head(element: etree._Element, at: int) -> LoopSite | None:
        """The loop's attributes; None when the schema refuses them (it says why)."""
        var = (element.get("var") or "").strip()
        if element.tag == "for_each":
            values, index = element.get("in"), (element.get("index") or "").strip()
            if not var or values is None or not values.strip():
                return None
            return LoopSite("for_each", at, var, index or INDEX, values=values, named=(var, index) if index else (var,))
        count = (element.get("count") or "").strip()
        if not count.isdigit() or not 1 <= int(count) <= 10_000:
            return None
        return LoopSite("repeat", at, var or INDEX, count=int(count), named=(var,) if var else ())

    def read_robot(self, root: etree._Element, at: int) -> RobotModel | None:
        name = root.get("robot")
        if not name:
            return None  # the schema reports it
        if name == CELL_ROBOT:
            return self.read_cell_robots(root, at)
        try:
            return find_robot(name)
        except KeyError as error:
            self.error(self.source.attribute_offset(at, "robot"), str(error.args[0]))
            return None

    def read_cell_robots(self, root: etree._Element, at: int) -> RobotModel | None:
        """``robot="cell"``: every robot the cell file lists (core_functions/cell_robots.py); the cell's own
        problems are reported where the application reads its cell."""
        cell_name = root.get("cell")
        if not cell_name or not cell_name.strip():
            self.error(self.source.attribute_offset(at, "robot"), 'robot="cell" runs on the robots its cell lists: give the cell file (cell=...)')
            return None
        cell, _ = read_cell_log(self.doc.path.parent / cell_name, fits=False)
        if cell is None:
            return None
        if not cell.robots:
            self.error(self.source.attribute_offset(at, "robot"), f'robot="cell": cell {cell_name} lists no <robot>; list its robots there or name the robot here')
            return None
        return cell_robot_model(cell.name, cell.robots)

    def read_cell_reference(self, root: etree._Element, at: int, draft: ApplicationDraft) -> None:
        cell = root.get("cell")
        if cell is None or not cell.strip():
            return
        draft.cell_where = self.source.attribute_at(at, "cell")
        draft.cell_path = self.doc.path.parent / cell
        draft.cell_display = os.path.normpath(os.path.join(os.path.dirname(self.source.file), cell))

    def read_policy(self, element: etree._Element, at: int) -> PolicySite:
        policy = PolicySite(at=at)
        retries = element.get("retries")
        if retries is not None and retries.strip().isdigit():
            policy.retries = int(retries)
        policy.action = element.get("action")
        policy.safe_pose = element.get("safe_pose")
        policy.alarm_timeout = self.bounded(element, at, "alarm_timeout", limits.BY_UNIT["s"])
        policy.safe_speed = _number(element.get("safe_speed"))
        policy.retreat = _number(element.get("retreat"))
        return policy

    def bounded(self, element: etree._Element, at: int, attribute: str, bound: limits.Bound) -> float | None:
        """A number of ``<error_policy>`` inside its physical bound (the XSD checks only its form)."""
        value = _number(element.get(attribute))
        if value is None:
            return None
        problem = bound.violation(attribute, value)
        if problem is not None:
            self.error(self.source.attribute_offset(at, attribute), f"<{element.tag}> {problem}")
            return None
        return value

    def read_operation(self, element: etree._Element, at: int, robot: RobotModel | None) -> OperationSite | None:
        op_id = element.get("id")
        operation = OperationSite(id=(op_id or "").strip(), name=element.get("name"), at=at, breakpoint=element.get("break") in BREAK_TRUE)
        unsafe = None if operation.id.isascii() and operation.id.isprintable() else unsafe_character(operation.id)
        if unsafe is not None:  # consoles, traces and the page show ids: none may reorder or hide what follows it
            self.error(self.source.attribute_offset(at, "id"), f"operation id '{printable(operation.id)}' holds {unsafe}, which makes "
                       "an id look like another on a console or a page; use letters, digits and punctuation")
        walk = self.walk
        for child in element:
            group = child.tag
            if not isinstance(group, str):
                continue
            child_at = walk.visit(child)
            if group not in GROUP_TAGS and group not in self.groups:  # a cell's own group names are the robot's
                walk.skip(child)  # the schema reports unknown elements
                continue
            call = self.read_call(child, group)
            if robot is not None and group not in self.groups:
                self.error(child_at, f"{group} is not a group of {robot.name} (its groups: {', '.join(robot.group_names)})")
                continue
            if call is None:
                continue
            first = operation.calls.get(group)
            if first is not None:
                line = self.source.at_offset(first.at).line
                self.error(child_at, f"group {group} appears twice in operation {operation.id} (first on line {line})")
                continue
            operation.calls[group] = call
        return operation if op_id is not None else None

    def read_valid_operation(self, element: etree._Element, at: int, robot: RobotModel | None) -> OperationSite:
        """:meth:`read_operation` of a file the parser found valid against the schema, which says
        what each element holds: groups of exactly one ``<function name>``, at most one ``<params>``,
        and in it only ``<param value>`` elements, with nothing inside.  So no tag is asked for
        below the group and nothing is skipped; each offset is still checked against the text
        (:meth:`DocumentWalk.at` when it disagrees), as in the general reader."""
        op_id = element.get("id") or ""
        operation = OperationSite(id=op_id.strip(), name=element.get("name"), at=at, breakpoint=element.get("break") in BREAK_TRUE)
        unsafe = None if operation.id.isascii() and operation.id.isprintable() else unsafe_character(operation.id)
        if unsafe is not None:
            self.error(self.source.attribute_offset(at, "id"), f"operation id '{printable(operation.id)}' holds {unsafe}, which makes "
                       "an id look like another on a console or a page; use letters, digits and punctuation")
        walk = self.walk
        offsets, text = walk.offsets, walk.text
        index = walk.next
        last = len(offsets) if walk.aligned else -1
        calls = operation.calls
        shared = self.shared.setdefault
        for child in element:
            tag = child.tag
            group = shared(tag, tag)  # type: ignore[arg-type]
            if index < last and text.startswith(group, offsets[index] + 1):
                child_at = offsets[index]
            else:
                child_at, last = walk.at(index, child), -1
            index += 1
            call: CallSite | None = None
            for function in child:
                if index < last and text.startswith("function", offsets[index] + 1):
                    function_at = offsets[index]
                else:
                    function_at, last = walk.at(index, function), -1
                index += 1
                values: list[str] = []
                param_at: list[int] = []
                names: list[str | None] | None = None
                for holder in function:
                    if not (index < last and text.startswith("params", offsets[index] + 1)):
                        walk.at(index, holder)
                        last = -1
                    index += 1
                    for param in holder:
                        if index < last and text.startswith("param", offsets[index] + 1):
                            param_at.append(offsets[index])
                        else:
                            param_at.append(walk.at(index, param))
                            last = -1
                        index += 1
                        value = param.get("value", "")
                        values.append(shared(value, value))
                        name = param.get("name")
                        if name is not None and names is None:
                            names = [None] * (len(values) - 1)
                        if names is not None:
                            names.append(name)
                function_name = function.get("name", "")
                call = CallSite(
                    group, shared(function_name, function_name), tuple(values), tuple(param_at), function_at,
                    tuple(names) if names is not None else None,
                )
            if call is None:
                continue
            if robot is not None and group not in self.groups:
                self.error(child_at, f"{group} is not a group of {robot.name} (its groups: {', '.join(robot.group_names)})")
                continue
            first = calls.get(group)
            if first is not None:
                line = self.source.at_offset(first.at).line
                self.error(child_at, f"group {group} appears twice in operation {operation.id} (first on line {line})")
                continue
            calls[group] = call
        walk.next = index
        return operation

    def read_call(self, group_element: etree._Element, group: str) -> CallSite | None:
        """The group's first ``<function>``; every element below the group is visited.

        The hottest loop of loading (once per param of a 10^5-call file), hence the local names
        and the walk's visit done inline: the n-th element in document order starts at the n-th
        offset of the scan when the text there is ``<`` and its name (:meth:`DocumentWalk.at`
        otherwise, which also falls back to the map of elements)."""
        walk = self.walk
        offsets, text = walk.offsets, walk.text
        index = walk.next
        last = len(offsets) if walk.aligned else -1
        call: CallSite | None = None
        complete = True
        for function in group_element:
            tag = function.tag
            if not isinstance(tag, str):
                continue
            if index < last and text.startswith(tag, offsets[index] + 1):
                at = offsets[index]
            else:
                at = walk.at(index, function)
                last = -1
            index += 1
            if tag != "function" or call is not None:
                walk.next = index
                walk.skip(function)  # the schema reports it
                index = walk.next
                continue
            values: list[str] = []
            param_at: list[int] = []
            names: list[str | None] | None = None
            for holder in function:
                tag = holder.tag
                if not isinstance(tag, str):
                    continue
                if not (index < last and text.startswith(tag, offsets[index] + 1)):
                    walk.at(index, holder)
                    last = -1
                index += 1
                if tag != "params":
                    walk.next = index
                    walk.skip(holder)
                    index = walk.next
                    continue
                for param in holder:
                    tag = param.tag
                    if not isinstance(tag, str):
                        continue
                    if index < last and text.startswith(tag, offsets[index] + 1):
                        offset = offsets[index]
                    else:
                        offset = walk.at(index, param)
                        last = -1
                    index += 1
                    if len(param):
                        walk.next = index
                        walk.skip(param)
                        index = walk.next
                    value = param.get("value")
                    if tag != "param" or value is None:
                        complete = False  # the schema reports it; checking the count would add noise
                        continue
                    name = param.get("name")
                    if name is not None and names is None:
                        names = [None] * len(values)
                    if names is not None:
                        names.append(name)
                    values.append(self.shared.setdefault(value, value))
                    param_at.append(offset)
            name = function.get("name")
            call = CallSite(group, name or "", tuple(values), tuple(param_at), at, tuple(names) if names is not None else None)
            complete = complete and bool(name)
        walk.next = index
        return call if complete else None


def _number(text: str | None) -> float | None:
    """An error_policy number as written; None when absent or not a number (the XSD reports it)."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        return None
