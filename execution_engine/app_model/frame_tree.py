"""The frame tree of a cell: which frames reach the world, in what order, and which form cycles.

Every frame names its parent; the world pose of a frame is the product of the poses down the
chain from ``world``.  The first version walked each frame's chain to the world and searched the
walked list for repeats: a chain of n frames cost n³/6 steps (5,000 frames: hours).  Here every
frame is looked at once: a walk stops at the first frame already placed, and a frame met twice in
one walk closes a cycle.  Iterative, so a chain of any length needs no recursion.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

WORLD = "world"


@dataclass
class FrameOrder:
    """Frames whose chain reaches the world, parents first; the cycles, each starting at its
    member written first; frames in or hanging below a cycle or an unknown parent (``broken``)."""

    order: list[str] = field(default_factory=list)
    cycles: list[list[str]] = field(default_factory=list)
    broken: set[str] = field(default_factory=set)
    unknown: dict[str, str] = field(default_factory=dict)  # a frame whose parent is not a frame -> that parent


def order_frames(parents: Mapping[str, str]) -> FrameOrder:
    """Sort the frames of ``{frame: parent}`` parents first, in one look-up per frame."""
    result = FrameOrder()
    placed: set[str] = set()  # in order (reaches the world) or broken: never walked again
    written: dict[str, int] | None = None  # document order, for naming a cycle from its first frame
    for name in parents:
        if name in placed:
            continue
        parent = parents.get(name)
        if parent == WORLD or (parent in placed and parent not in result.broken):
            result.order.append(name)  # the common case: below a frame already placed
            placed.add(name)
            continue
        path: dict[str, int] = {}  # the frames of this walk, in walking order
        current = name
        while parent is not None:
            if parent != WORLD and parent not in parents:
                result.unknown[current] = parent
            path[current] = len(path)
            current = parent
            if current == WORLD or current in placed or current in path:
                break
            parent = parents.get(current)
        walked = list(path)
        if current in path:  # the walk came back to itself
            written = written or {n: i for i, n in enumerate(parents)}
            cycle = walked[path[current]:]
            first = min(range(len(cycle)), key=lambda i: written[cycle[i]])
            result.cycles.append(cycle[first:] + cycle[:first])
            result.broken.update(walked)
        elif current == WORLD or (current in placed and current not in result.broken):
            result.order.extend(reversed(walked))
        else:
            result.broken.update(walked)
        placed.update(walked)
    return result
