"""``<robot>`` of a cell file: a robot of a mixed cell, checked where it is written.

Each problem is one diagnostic at the robot's tag or the attribute at fault: an unknown model or
back end, a base pose not given (a robot placed by default at the world's origin would stand
inside another one unnoticed), a robot name, a group or a joint already taken by an earlier robot
(the application names groups, /joint_states joints, so each must belong to one robot: ``prefix`` and
``<group name as>`` name them apart), a ``<group>`` naming a group the model lacks, an option written twice.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol

from lxml import etree

from core_functions.cell_robots import BACKEND_NAMES, CellNames, CellRobot
from core_functions.geometry import Pose
from core_functions.robots import find_robot


class RobotSite(Protocol):
    """What the cell reader offers: reporting at a tag or attribute, and poses in the file's units."""

    def report(self, at: int, attribute: str | None, message: str) -> None: ...

    def pose(self, element: etree._Element, at: int, label: str) -> Pose | None: ...


def read_robot(
    site: RobotSite, element: etree._Element, at: int, children: list[tuple[etree._Element, int]], robots: list[CellRobot], lines: dict[str, int], line: int,
) -> None:
    """Append the ``<robot>`` at ``at`` to ``robots`` (``children``: its ``<option>`` and ``<group>`` elements with
    their offsets; ``lines``: each robot's, group's and joint's line, for the messages)."""
    name = element.get("name")
    model_name = element.get("model")
    if not name or not model_name:
        return  # the schema reports it
    label = repr(name)
    if f"robot {name}" in lines:
        site.report(at, "name", f"robot {label} is listed twice (first on line {lines[f'robot {name}']}); give each robot its own name")
        return
    lines[f"robot {name}"] = line
    try:
        model = find_robot(model_name)
    except KeyError as error:
        site.report(at, "model", f"robot {label}: {error.args[0]}")
        return
    backend = element.get("backend", model.default_backend)
    if backend not in BACKEND_NAMES:
        site.report(at, "backend", f"robot {label}: unknown back end {backend!r} (choose from: {', '.join(BACKEND_NAMES)})")
        return
    if element.get("xyz") is None or element.get("rpy") is None:
        missing = " and ".join(a for a in ("xyz", "rpy") if element.get(a) is None)
        site.report(at, None, f"robot {label}: its base pose is missing ({missing}): say where its base stands in the cell's world frame (xyz, rpy; 0 0 0 for the origin)")
        return
    base = site.pose(element, at, label)
    if base is None:
        return  # the bound or the number is reported
    named = read_names(site, element, at, children, label, model.group_names)
    if named is None:
        return
    names, written = named
    cell_groups = [(names.group(own), own) for own in model.group_names]
    for group, own in cell_groups:
        taken = lines.get(f"group {group}")
        if taken is not None:
            renamed = "" if group == own else f" (its {own!r} renamed)"
            where, field = (written[own], "as") if own in written else (at, "prefix" if names.prefix else "model")
            site.report(where, field, (
                f"robot {label}: group {group!r}{renamed} of {model.name} is already a group of the robot on line {taken}; "
                f"each group of a cell belongs to one robot (the application names groups): name this robot's apart with "
                f"prefix=\"...\" or <group name=\"{own}\" as=\"...\"/>"
            ))
            return
    for own in model.joint_names:
        joint = names.joint(own)
        taken = lines.get(f"joint {joint}")
        if taken is not None:
            site.report(at, "prefix" if names.prefix else "model", (
                f"robot {label}: joint {joint!r} of {model.name} is already a joint of the robot on line {taken}; "
                f"/joint_states would carry both: give this robot a prefix=\"...\" of its own"
            ))
            return
    options: dict[str, str] = {}
    for key, value, _ in pairs(children, "option", "value"):
        if key in options:
            site.report(at, None, f"robot {label}: option {key!r} is given twice")
            return
        options[key] = value
    for group, _ in cell_groups:
        lines[f"group {group}"] = line
    for own in model.joint_names:
        lines[f"joint {names.joint(own)}"] = line
    robots.append(CellRobot(name, model, base, backend, tuple(options.items()), names))


def pairs(children: list[tuple[etree._Element, int]], tag: str, second: str) -> Iterator[tuple[str, str, int]]:
    """Each ``<tag name second>`` child's two values and where it is written (one lacking either: the schema reports it)."""
    for child, child_at in children:
        first, other = child.get("name"), child.get(second)
        if child.tag == tag and first is not None and other is not None:
            yield first, other, child_at


def read_names(
    site: RobotSite, element: etree._Element, at: int, children: list[tuple[etree._Element, int]], label: str, groups: tuple[str, ...],
) -> tuple[CellNames, dict[str, int]] | None:
    """How the cell names the robot's groups and joints (``prefix`` and each ``<group name as>``) and where each
    ``<group>`` is written; None when a ``<group>`` names a group the model lacks, is given twice, or two of
    its groups would get one name."""
    renamed: dict[str, str] = {}
    written: dict[str, int] = {}
    for own, named, child_at in pairs(children, "group", "as"):
        if own not in groups:
            site.report(child_at, "name", f"robot {label}: its model has no group {own!r} (its groups: {', '.join(groups)})")
            return None
        if own in renamed:
            site.report(child_at, "name", f"robot {label}: group {own!r} is named twice")
            return None
        renamed[own] = named
        written[own] = child_at
    names = CellNames(element.get("prefix", ""), tuple(renamed.items()))
    seen: dict[str, str] = {}
    for own in groups:
        group = names.group(own)
        if group in seen:
            site.report(written.get(own, at), "as" if own in written else None, f"robot {label}: its groups {seen[group]!r} and {own!r} would both be {group!r} in the cell")
            return None
        seen[group] = own
    return names, written
