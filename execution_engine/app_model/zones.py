"""Interference zones of a cell: boxes where only one group may work at a time.

``<zone name="at_part" parent="part" xyz="0 0 0.05" size="0.16 0.24 0.14"/>`` is a box with the
axes of its parent frame (default ``world``), centred at ``xyz`` in it (the cell's length unit).
A call works in a zone when a frame it names (a hole, a slot, a target) lies inside the box; with
``sync="flags"`` the engine lets one group at a time into a zone, in application order
(execution_engine/engine/zones.py), and ``validate`` checks that the order cannot deadlock with
the flags (app_model/flag_check.py).
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from core_functions.geometry import Pose
from execution_engine.app_model.diagnostics import Location


@dataclass(frozen=True)
class Zone:
    """A zone: its parent frame, centre in it and side lengths (m)."""

    name: str
    parent: str
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    location: Location | None = None

    def contains(self, parent_pose: Pose, point: tuple[float, float, float]) -> bool:
        """Whether a world point lies in the box, the parent frame being at ``parent_pose``."""
        m = parent_pose.matrix()
        local = m[:3, :3].T @ (np.array(point) - m[:3, 3]) - np.array(self.centre)
        return bool(np.all(np.abs(local) <= 0.5 * np.array(self.size) + 1e-9))


def call_zones(cell: object, params: Iterable[str]) -> tuple[str, ...]:
    """The zones a call works in: those holding a cell frame its params name (in the cell's zone order)."""
    zones = getattr(cell, "zones", None)
    if not zones:
        return ()
    frames = [p for text in params for p in text.replace(",", " ").split() if p in cell.frames]  # type: ignore[attr-defined]
    inside = []
    for zone in zones.values():
        parent = cell.pose(zone.parent)  # type: ignore[attr-defined]
        if any(zone.contains(parent, cell.pose(f).position) for f in frames):  # type: ignore[attr-defined]
            inside.append(zone.name)
    return tuple(inside)
