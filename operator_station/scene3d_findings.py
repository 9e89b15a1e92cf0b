"""The dry run's findings and a run's collision faults, placed for the 3D view: which two bodies a collision
is between, where an unreachable target is, and when.

The dry run refuses a run with its diagnostics (``FILE:LINE:COL: operation OP GROUP FUNCTION: KIND: DETAIL
(at T s)``, :mod:`cell_runner.dry_run.report`), which the station shows as the run's messages; a run that meets
a collision (a simulator's own check, a controller's) ends the call with an error naming the bodies as the
collision model labels them (:meth:`robot_bridges.collision.scene.Body.label`: ``left_arm hand
(LARM_JOINT5_Link)``, ``left_arm LARM_JOINT3_Link``, ``cell part``, ``robot WAIST``).  A text that says
neither is not a finding the view can place, and is left to the messages.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from core_functions.geometry import Pose

#: Characters of a message read at most (a diagnostic is a line; a crafted one is cut, not scanned whole).
MAX_TEXT = 4000
_DIAGNOSTIC = re.compile(
    r"^(?P<file>.*?):(?P<line>\d+):(?P<col>\d+): operation (?P<operation>\S+)(?: \([^()]*\))? (?P<group>\S+) (?P<function>\S+): "
    r"(?P<kind>[a-z_]+): (?P<detail>.*)$"
)
_WHEN = re.compile(r"\((?:at (?P<at>\d+(?:\.\d+)?) s|[^()]*first at (?P<first>\d+(?:\.\d+)?) s)\)\s*$")
_BETWEEN = re.compile(r"collision between (?P<a>.+?) and (?P<b>.+?)(?=, against |\s*$| - |\s+\(at )")
_MARGIN = re.compile(r"collision margin: (?P<a>.+?) and (?P<b>.+?) \d+(?:\.\d+)? mm apart")
_NUMBER = r"(-?\d+(?:\.\d+)?)"
_TARGET = re.compile(rf"\({_NUMBER}, {_NUMBER}, {_NUMBER}\) m, rpy \({_NUMBER}, {_NUMBER}, {_NUMBER}\) deg")
_PRIMITIVE = re.compile(r"\b(?:move_cartesian|move_relative|move_joints)\((?P<label>[^,()]*)")


@dataclass(frozen=True)
class Body:
    """One body of a collision: whose (a group, ``cell``, ``robot``), its name (a link, a cell frame), its label."""

    owner: str
    name: str
    label: str

    def to_json(self) -> dict[str, str]:
        return {"owner": self.owner, "name": self.name, "label": self.label}


def body(label: str) -> Body:
    """A body from its label: ``GROUP hand (LINK)``, ``GROUP LINK``, ``cell FRAME``, ``robot LINK``."""
    label = label.strip()
    owner, _, rest = label.partition(" ")
    inner = re.fullmatch(r".*\((?P<name>[^()]+)\)", rest)
    name = inner.group("name") if inner else rest
    return Body(owner, name.strip() or owner, label)


def collision_bodies(text: str) -> tuple[Body, Body] | None:
    """The two bodies a collision text names, or None."""
    match = _BETWEEN.search(text) or _MARGIN.search(text)
    return (body(match.group("a")), body(match.group("b"))) if match else None


def target_pose(text: str) -> Pose | None:
    """The first TCP target a text gives as ``(x, y, z) m, rpy (r, p, y) deg``, or None."""
    match = _TARGET.search(text)
    if match is None:
        return None
    x, y, z, r, p, w = (float(v) for v in match.groups())
    if not all(math.isfinite(v) and abs(v) < 1e6 for v in (x, y, z, r, p, w)):
        return None
    return Pose.from_xyz_rpy(x, y, z, math.radians(r), math.radians(p), math.radians(w))


def placed(kind: str, detail: str) -> dict[str, Any] | None:
    """What of a problem the view can place: the bodies of a collision, the pose of an unreachable target."""
    if kind == "collision":
        bodies = collision_bodies(detail)
        return {"bodies": [b.to_json() for b in bodies]} if bodies is not None else None
    if kind in ("unreachable", "joint_limit", "singularity"):
        pose = target_pose(detail)
        label = _PRIMITIVE.search(detail)
        if pose is None:
            return None
        return {"target": [pose.x, pose.y, pose.z, pose.qx, pose.qy, pose.qz, pose.qw], "label": label.group("label").strip() if label else ""}
    return None


def dry_run_finding(text: str) -> dict[str, Any] | None:
    """A finding of the dry run from its diagnostic line, placed; None for a line that is no placeable finding."""
    text = text[:MAX_TEXT]
    match = _DIAGNOSTIC.match(text)
    if match is None:
        return None
    where = placed(match.group("kind"), match.group("detail"))
    if where is None:
        return None
    when = _WHEN.search(text)
    t = float(when.group("at") or when.group("first")) if when else None
    return {"source": "dry run", "kind": match.group("kind"), "group": match.group("group"), "operation": match.group("operation"),
            "function": match.group("function"), "line": int(match.group("line")), "t": t, "message": text, **where}


def run_finding(record: dict[str, Any]) -> dict[str, Any] | None:
    """A collision or unreachable fault a run's ``error`` record reports, placed at the record's time; None otherwise."""
    text = record.get("error")
    t = record.get("t")
    if record.get("event") != "error" or not isinstance(text, str) or not isinstance(t, (int, float)) or isinstance(t, bool):
        return None
    text = text[:MAX_TEXT]
    for kind in ("collision", "unreachable", "joint_limit"):
        if f"{kind}:" in text:
            where = placed(kind, text)
            if where is not None:
                return {"source": "run", "kind": kind, "group": str(record.get("group", "")), "operation": str(record.get("operation") or ""),
                        "function": str(record.get("function") or ""), "line": None, "t": float(t), "message": text, **where}
    return None


def findings(messages: list[dict[str, Any]], records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every placeable finding: the dry run's (from the run's messages) then the run's own (from its records)."""
    out = [f for m in messages if isinstance(m, dict) and isinstance(m.get("message"), str) if (f := dry_run_finding(m["message"])) is not None]
    out += [f for r in records if isinstance(r, dict) and r.get("event") == "error" if (f := run_finding(r)) is not None]
    return out
