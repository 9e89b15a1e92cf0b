"""The dry run's findings and a run's collision faults, placed for the 3D view: which two bodies a collision
is between, where an unreachable target is, when, and -- for the dry run's -- where the robot was then.

The dry run's findings are its report's data (:class:`cell_runner.dry_run.report.Finding`: the bodies, the target,
every joint at the finding's instant), never read back from its message.  A run that meets a collision (a
simulator's own check, a controller's) ends the call with an error record naming the bodies as the collision model
labels them (:meth:`robot_bridges.collision.scene.Body.label`: ``left_arm hand (LARM_JOINT5_Link)``, ``left_arm
LARM_JOINT3_Link``, ``cell part``, ``robot WAIST``): that text is all a record says, so it is read.  A text that
says neither is not a finding the view can place, and is left to the messages.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from cell_runner.dry_run.report import Finding
from core_functions.geometry import Pose

#: Characters of a message read at most (a diagnostic is a line; a crafted one is cut, not scanned whole).
MAX_TEXT = 4000
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


def dry_run_finding(finding: Finding) -> dict[str, Any] | None:
    """A finding of the dry run, placed from its data: the bodies of a collision or the target refused, its time, the
    robot's joints then (by name); None for one the view cannot place (a function's own failure)."""
    if finding.bodies:
        where: dict[str, Any] = {"bodies": [{"owner": b.owner, "name": b.name, "label": b.label} for b in finding.bodies]}
    elif finding.target is not None:
        t = finding.target
        where = {"target": [t.x, t.y, t.z, t.qx, t.qy, t.qz, t.qw], "label": finding.primitive}
    else:
        return None
    joints = {name: float(value) for name, value in zip(*finding.joints)} if finding.joints is not None else None
    return {"source": "dry run", "kind": finding.kind, "group": finding.group, "operation": finding.operation, "function": finding.function,
            "line": finding.line, "t": finding.t, "message": str(finding.diagnostic())[:MAX_TEXT], "joints": joints, **where}


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
