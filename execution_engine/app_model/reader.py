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

from lxml import etree

from core_functions import limits
from core_functions.printable import printable, unsafe_character
from core_functions.robots import RobotModel, find_robot
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, Location
from execution_engine.app_model.positions import DocumentWalk, SourceMap
from execution_engine.app_model.safe_xml import XmlDocument

GROUP_TAGS = frozenset({"left_arm", "right_arm", "torso_head", "arm"})  # as in application.xsd


@dataclass(slots=True)
class ParamSite:
    """One ``<param>`` as written; ``at`` is the offset of its start tag."""

    value: str
    name: str | None
    at: int


@dataclass(slots=True)
class CallSite:
    """One group's ``<function>`` (``at``: its offset), or the implicit wait of a group left out."""

    group: str
    function: str
    params: list[ParamSite]
    at: int
    implicit: bool = False


@dataclass(slots=True)
class OperationSite:
    id: str
    name: str | None
    at: int
    calls: dict[str, CallSite] = field(default_factory=dict)


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
    source: SourceMap
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


class ApplicationReader:
    def __init__(self, doc: XmlDocument, log: DiagnosticLog | None = None) -> None:
        self.doc = doc
        self.source = doc.source
        self.walk = DocumentWalk(doc.source)
        self.diagnostics = log if log is not None else DiagnosticLog()
        self.groups: frozenset[str] = GROUP_TAGS

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
        for child in root:
            if not isinstance(child.tag, str):  # a comment or processing instruction
                continue
            at = self.walk.visit(child)
            if child.tag == "operation":
                operation = self.read_operation(child, at, draft.robot)
                if operation is None:
                    continue
                first = ids.get(operation.id)
                if first is not None:
                    line = self.source.at_offset(first.at).line
                    self.error(self.source.attribute_offset(at, "id"), f"operation id {operation.id!r} is used twice (first on line {line})")
                else:
                    ids[operation.id] = operation
                draft.operations.append(operation)
                continue
            if child.tag == "description":
                draft.description = (child.text or "").strip()
            elif child.tag == "error_policy" and draft.policy is None:
                draft.policy = self.read_policy(child, at)
            self.walk.skip(child)
        return draft

    def read_robot(self, root: etree._Element, at: int) -> RobotModel | None:
        name = root.get("robot")
        if not name:
            return None  # the schema reports it
        try:
            return find_robot(name)
        except KeyError as error:
            self.error(self.source.attribute_offset(at, "robot"), str(error.args[0]))
            return None

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
        operation = OperationSite(id=(op_id or "").strip(), name=element.get("name"), at=at)
        unsafe = unsafe_character(operation.id)
        if unsafe is not None:  # consoles, traces and the page show ids: none may reorder or hide what follows it
            self.error(self.source.attribute_offset(at, "id"), f"operation id '{printable(operation.id)}' holds {unsafe}, which makes "
                       "an id look like another on a console or a page; use letters, digits and punctuation")
        for child in element:
            if not isinstance(child.tag, str):
                continue
            child_at = self.walk.visit(child)
            group = child.tag
            if group not in GROUP_TAGS:
                self.walk.skip(child)  # the schema reports unknown elements
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

    def read_call(self, group_element: etree._Element, group: str) -> CallSite | None:
        """The group's first ``<function>``; every element below the group is visited.

        The hottest loop of loading (once per param of a 10^5-call file), hence the local names
        and the inlined element tests.
        """
        visit, skip = self.walk.visit, self.walk.skip
        call: CallSite | None = None
        complete = True
        for function in group_element:
            if not isinstance(function.tag, str):
                continue
            at = visit(function)
            if function.tag != "function" or call is not None:
                skip(function)  # the schema reports it
                continue
            params: list[ParamSite] = []
            for holder in function:
                if not isinstance(holder.tag, str):
                    continue
                visit(holder)
                if holder.tag != "params":
                    skip(holder)
                    continue
                for param in holder:
                    tag = param.tag
                    if not isinstance(tag, str):
                        continue
                    param_at = visit(param)
                    if len(param):
                        skip(param)
                    value = param.get("value")
                    if tag != "param" or value is None:
                        complete = False  # the schema reports it; checking the count would add noise
                        continue
                    params.append(ParamSite(value, param.get("name"), param_at))
            name = function.get("name")
            call = CallSite(group, name or "", params, at)
            complete = complete and bool(name)
        return call if complete else None


def _number(text: str | None) -> float | None:
    """An error_policy number as written; None when absent or not a number (the XSD reports it)."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        return None
