"""``<robot>`` of a cell file: a robot of a mixed cell, checked where it is written.

Each problem is one diagnostic at the robot's tag or the attribute at fault: an unknown model or
back end, a base pose not given (a robot placed by default at the world's origin would stand
inside another one unnoticed), a robot name or a group already taken by an earlier robot (the
application names groups, so a group must belong to one robot), an option written twice.
"""
from __future__ import annotations

from typing import Protocol

from lxml import etree

from core_functions.cell_robots import BACKEND_NAMES, CellRobot
from core_functions.geometry import Pose
from core_functions.robots import find_robot


class RobotSite(Protocol):
    """What the cell reader offers: reporting at a tag or attribute, and poses in the file's units."""

    def report(self, at: int, attribute: str | None, message: str) -> None: ...

    def pose(self, element: etree._Element, at: int, label: str) -> Pose | None: ...


def read_robot(site: RobotSite, element: etree._Element, at: int, robots: list[CellRobot], lines: dict[str, int], line: int) -> None:
    """Append the ``<robot>`` at ``at`` to ``robots`` (``lines``: each robot's and group's line, for the messages)."""
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
    for group in model.group_names:
        taken = lines.get(f"group {group}")
        if taken is not None:
            site.report(at, "model", (
                f"robot {label}: group {group!r} of {model.name} is already a group of the robot on line {taken}; "
                f"a cell's robots need groups of their own names (the application names groups), so robots whose models share a "
                f"group name (two KUKAs, a KUKA and a Viper: each 'arm') cannot share one cell"
            ))
            return
    options: dict[str, str] = {}
    for child in element:
        if not isinstance(child.tag, str) or child.tag != "option":
            continue
        key, value = child.get("name"), child.get("value")
        if key is None or value is None:
            continue  # the schema reports it
        if key in options:
            site.report(at, None, f"robot {label}: option {key!r} is given twice")
            return
        options[key] = value
    for group in model.group_names:
        lines[f"group {group}"] = line
    robots.append(CellRobot(name, model, base, backend, tuple(options.items())))
