"""Read an application document into drafts that remember where everything was written.

The reader runs after the schema check whatever its outcome, so one run reports structural and
semantic problems together.  It therefore never trusts the shape of the document: what it cannot
interpret it skips silently (the schema has said why), and it reports only what a schema cannot
know -- the robot, the robot's groups, repeated ids and groups, the cell file.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

from core_functions.robots import RobotModel, find_robot
from execution_engine.app_model.diagnostics import Diagnostic, Location
from execution_engine.app_model.positions import SourceMap
from execution_engine.app_model.safe_xml import XmlDocument

GROUP_TAGS = frozenset({"left_arm", "right_arm", "torso_head", "arm"})  # as in application.xsd


@dataclass
class ParamSite:
    """One ``<param>`` as written."""

    value: str
    name: str | None
    element: etree._Element


@dataclass
class CallSite:
    """One group's ``<function>`` (or the implicit wait of a group left out)."""

    group: str
    function: str
    params: list[ParamSite]
    where: Location
    element: etree._Element | None  # None: implicit

    @property
    def implicit(self) -> bool:
        return self.element is None


@dataclass
class OperationSite:
    id: str
    name: str | None
    where: Location
    calls: dict[str, CallSite] = field(default_factory=dict)


@dataclass
class PolicySite:
    """``<error_policy>`` as written; values the schema rejected are left at None."""

    where: Location
    retries: int | None = None
    action: str | None = None
    safe_pose: str | None = None
    safe_pose_where: Location | None = None
    alarm_timeout: float | None = None


@dataclass
class ApplicationDraft:
    doc: XmlDocument
    name: str
    robot: RobotModel | None
    cell_path: Path | None = None
    cell_display: str | None = None
    cell_where: Location | None = None
    description: str = ""
    version: str | None = None
    policy: PolicySite | None = None
    operations: list[OperationSite] = field(default_factory=list)

    @property
    def source(self) -> SourceMap:
        return self.doc.source


class ApplicationReader:
    def __init__(self, doc: XmlDocument) -> None:
        self.doc = doc
        self.source = doc.source
        self.diagnostics: list[Diagnostic] = []
        self.groups: frozenset[str] = GROUP_TAGS

    def error(self, where: Location, message: str) -> None:
        self.diagnostics.append(Diagnostic.at(where, message))

    def read(self) -> ApplicationDraft:
        root = self.doc.root
        draft = ApplicationDraft(doc=self.doc, name=root.get("name", ""), robot=self.read_robot(root))
        draft.version = root.get("version")
        self.read_cell_reference(root, draft)
        ids: dict[str, OperationSite] = {}
        self.groups = frozenset(draft.robot.group_names) if draft.robot is not None else GROUP_TAGS
        for child in root.iterchildren(etree.Element):
            if child.tag == "description":
                draft.description = (child.text or "").strip()
            elif child.tag == "error_policy" and draft.policy is None:
                draft.policy = self.read_policy(child)
            elif child.tag == "operation":
                operation = self.read_operation(child, draft.robot)
                if operation is None:
                    continue
                first = ids.get(operation.id)
                if first is not None:
                    self.error(self.source.attribute(child, "id"), f"operation id {operation.id!r} is used twice (first on line {first.where.line})")
                else:
                    ids[operation.id] = operation
                draft.operations.append(operation)
        return draft

    def read_robot(self, root: etree._Element) -> RobotModel | None:
        name = root.get("robot")
        if not name:
            return None  # the schema reports it
        try:
            return find_robot(name)
        except KeyError as error:
            self.error(self.source.attribute(root, "robot"), str(error.args[0]))
            return None

    def read_cell_reference(self, root: etree._Element, draft: ApplicationDraft) -> None:
        cell = root.get("cell")
        if cell is None or not cell.strip():
            return
        draft.cell_where = self.source.attribute(root, "cell")
        draft.cell_path = self.doc.path.parent / cell
        draft.cell_display = os.path.normpath(os.path.join(os.path.dirname(self.source.file), cell))

    def read_policy(self, element: etree._Element) -> PolicySite:
        policy = PolicySite(where=self.source.element(element))
        retries = element.get("retries")
        if retries is not None and retries.strip().isdigit():
            policy.retries = int(retries)
        policy.action = element.get("action")
        policy.safe_pose = element.get("safe_pose")
        if policy.safe_pose is not None:
            policy.safe_pose_where = self.source.attribute(element, "safe_pose")
        timeout = element.get("alarm_timeout")
        if timeout is not None:
            try:
                policy.alarm_timeout = float(timeout)
            except ValueError:
                pass
        return policy

    def read_operation(self, element: etree._Element, robot: RobotModel | None) -> OperationSite | None:
        op_id = element.get("id")
        if op_id is None:
            return None
        operation = OperationSite(id=op_id.strip(), name=element.get("name"), where=self.source.element(element))
        for child in element.iterchildren(etree.Element):
            group = child.tag
            if group not in GROUP_TAGS:
                continue  # the schema reports unknown elements
            if robot is not None and group not in self.groups:
                self.error(self.source.element(child), f"{group} is not a group of {robot.name} (its groups: {', '.join(robot.group_names)})")
                continue
            call = self.read_call(child)
            if call is None:
                continue
            first = operation.calls.get(group)
            if first is not None:
                self.error(self.source.element(child), f"group {group} appears twice in operation {operation.id} (first on line {first.where.line})")
                continue
            operation.calls[group] = call
        return operation

    def read_call(self, group_element: etree._Element) -> CallSite | None:
        function = next((c for c in group_element if c.tag == "function"), None)
        if function is None:
            return None
        name = function.get("name")
        if not name:
            return None
        params: list[ParamSite] = []
        for holder in function:  # plain iteration: the fastest way through lxml for 10^5 calls
            if holder.tag != "params":
                continue
            for param in holder:
                if param.tag != "param":
                    continue
                value = param.get("value")
                if value is None:
                    return None  # the schema reports it; checking the count would only add noise
                params.append(ParamSite(value, param.get("name"), param))
        return CallSite(group=group_element.tag, function=name, params=params, where=self.source.element(function), element=function)
