"""The bodies a collision check sees besides the robot's links: the cell's boxes and held parts.

Both come from the cell model as the engine publishes it (:class:`CellSnapshot`), so the dry run
and the simulator at run time check the same world:

* a frame with ``box="sx sy sz"`` (and optionally ``box_xyz``, the box's centre in the frame) is
  a solid box with the frame's axes -- a fixture, a part, a tray.  The cell reader has already
  converted both to metres and bounded them (execution_engine/app_model/cell_reader.py), so
  here they are plain SI numbers.
* a part held in a gripper is a capsule along the tool axis: an element with ``diameter`` and
  ``length`` (a rivet), gripped ``grip_depth`` below its top, as the rivet skills hold it.  Which
  element a closing gripper takes is the one of the slot frame nearest the TCP (within
  :data:`GRASP_REACH`): the simulator has no other way to know what it picked.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from core_functions.geometry import Pose
from node_transport.wire import CellSnapshot

#: A slot frame farther than this from the TCP when the gripper closes is not what it picked (m).
GRASP_REACH = 0.03


@dataclass(frozen=True)
class CellBox:
    """A solid box of the cell: its centre pose in the world, full side lengths (m), its frame."""

    frame: str
    pose: Pose
    size: tuple[float, float, float]


@dataclass(frozen=True)
class HeldPart:
    """A part in a gripper: a capsule on the tool axis from ``-top`` to ``+tip`` (m) past the TCP."""

    element: str
    radius: float
    top: float
    tip: float

    @property
    def length(self) -> float:
        return self.top + self.tip


def _numbers(text: str | None, count: int) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.replace(",", " ").split())
    except ValueError:
        return None
    return values if len(values) == count and all(math.isfinite(v) for v in values) else None


def cell_boxes(cell: CellSnapshot) -> tuple[CellBox, ...]:
    """Every ``box`` of the cell in the world (boxes the reader refused never get here)."""
    boxes = []
    for frame in cell.frames:
        size = _numbers(frame.attributes.get("box"), 3)
        if size is None or min(size) <= 0.0:
            continue
        centre = _numbers(frame.attributes.get("box_xyz"), 3) or (0.0, 0.0, 0.0)
        boxes.append(CellBox(frame.name, frame.pose.compose(Pose.from_xyz_rpy(*centre)), (size[0], size[1], size[2])))
    return tuple(boxes)


def _number(attributes: dict[str, str], key: str) -> float | None:
    values = _numbers(attributes.get(key), 1)
    return None if values is None else values[0]


def held_part(cell: CellSnapshot, tcp: Pose) -> HeldPart | None:
    """The part a gripper closing at ``tcp`` takes: the element of the nearest slot frame, or None."""
    best: tuple[float, str] | None = None
    for frame in cell.frames:
        element = frame.attributes.get("element")
        if element is None or element not in cell.elements:
            continue
        distance = frame.pose.distance_to(tcp)
        if distance <= GRASP_REACH and (best is None or distance < best[0]):
            best = (distance, element)
    if best is None:
        return None
    attributes = cell.elements[best[1]]
    diameter, length = _number(attributes, "diameter"), _number(attributes, "length")
    if diameter is None or length is None or diameter <= 0 or length <= 0:
        return None
    grip = min(max(_number(attributes, "grip_depth") or 0.0, 0.0), length)
    return HeldPart(best[1], diameter / 2.0, grip, length - grip)
