"""Interference zones of a cell: boxes where only one group may work at a time.

``<zone name="hands_left" parent="part" xyz="0 0.02 0.05" size="0.16 0.12 0.14"/>`` is a box with the
axes of its parent frame (default ``world``), centred at ``xyz`` in it (the cell's length unit).
A call works in a zone when a frame it names (a hole, a slot, a target) lies inside the box.  In
both modes the engine lets one group at a time into a zone, in application order
(execution_engine/engine/zones.py): a group's motion that ends in the box waits until no other
group is inside, and the group holds the zone until a motion of it ends outside the box again
(execution_engine/machine/zone_gate.py).  ``validate`` checks that the order cannot deadlock with
the flags and the operations (app_model/flag_check.py).  The group machines learn the boxes from
the cell snapshot: each zone is a frame of kind ``zone`` there (:func:`zone_frame`), its pose the
box's centre and axes in the world, its ``size`` attribute the sides in metres.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from core_functions.geometry import Pose, rotate
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
        return inside_box(parent_pose.compose(Pose.from_xyz_rpy(*self.centre)), self.size, point)


ZONE_KIND = "zone"  # the kind of a zone's frame in the cell snapshot
#: The sender of the engine's zone grants on the coordination topic (engine/zones.py).
ENGINE = "execution_engine"
_PREFIX = "zone:"


def zone_key(zone: str, request_id: str) -> str:
    """The coordination key of a group's request for ``zone`` during request ``request_id``."""
    return f"{_PREFIX}{zone}:{request_id}"


def parse_key(key: str) -> tuple[str, str] | None:
    """(zone, request id) of a zone key, None for any other key (a barrier's)."""
    if not key.startswith(_PREFIX):
        return None
    zone, _, request_id = key[len(_PREFIX):].rpartition(":")
    return (zone, request_id) if zone and request_id else None


def zone_frame(zone: Zone, parent_pose: Pose) -> tuple[Pose, dict[str, str]]:
    """A zone as a snapshot frame: its centre and axes in the world, and its sides (m) as attributes."""
    pose = parent_pose.compose(Pose.from_xyz_rpy(*zone.centre))
    return pose, {"size": " ".join(repr(float(x)) for x in zone.size)}


def inside_box(pose: Pose, size: tuple[float, float, float], point: tuple[float, float, float]) -> bool:
    """Whether a world point lies in the box centred at ``pose`` (its axes) with sides ``size``."""
    conjugate = (-pose.qx, -pose.qy, -pose.qz, pose.qw)  # into the box's axes; plain floats, so validate needs no numpy
    local = rotate(conjugate, (point[0] - pose.x, point[1] - pose.y, point[2] - pose.z))
    return all(abs(c) <= 0.5 * s + 1e-9 for c, s in zip(local, size))


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
