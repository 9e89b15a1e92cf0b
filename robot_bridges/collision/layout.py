"""The bodies of a collision scene as they are now, and the pairs of them that can meet.

A :class:`Layout` is built once for a state of the scene (its tools, held parts and cell boxes)
and used for every configuration until that state changes: which solids there are, where each
hangs on the robot, the pairs to measure, and each pair's *levers* -- how fast the pair's
distance can shrink per unit of speed of each joint (conservative advancement,
:mod:`robot_bridges.collision.sweep`).  Rebuilding it per configuration was most of a check's
cost; per motion it is nothing.

The lever of a solid about a revolute joint that carries it bounds the distance from that joint's
axis to any point of the solid, in every configuration: the lengths of the joint placements
between the joint and the solid's own joint, plus the distance from that joint to the centre of
the solid's bounding sphere, plus the sphere's radius.  A point at distance r from an axis
turning at w rad/s moves at most r*w m/s.  A joint carrying both solids of a pair moves them
together rigidly and cannot change their distance, so a pair's lever about it is 0; about any
other joint it is the lever of whichever of the two solids that joint carries.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from core_functions.geometry import Pose

Matrix = NDArray[np.float64]


class Placed(Protocol):
    """What a layout reads of its scene (robot_bridges/collision/scene.py's CollisionScene)."""

    model: Any  # pinocchio Model
    data: Any  # its Data: frame placements after place()
    gdata: Any  # the GeometryData: geometry placements after place()

    def place(self, q: NDArray[np.float64]) -> None: ...


class Hung(Protocol):
    """What a layout reads of a solid (scene.Solid): its body, shape, bounding sphere and the joint carrying it."""

    body: Any
    geometry: Any
    radius: float
    joint: int
    centre: NDArray[np.float64]


class Layout:
    """Solids, pairs and levers of a scene in one state (see the module docstring)."""

    def __init__(self, scene: Placed, solids: Sequence[Hung], attach: Sequence[tuple[str, Any]], box_start: int,
                 pairs: Sequence[tuple[int, int]], boxes: Sequence[tuple[Matrix, tuple[float, float, float]]], work_reach: float) -> None:
        self.scene = scene
        self.solids = list(solids)
        self.attach = list(attach)  # ("link", geometry index) | ("tcp", (frame id, offset)) | ("fixed", matrix)
        self.box_start = box_start
        self.boxes = list(boxes)
        self.work_reach = work_reach
        self.ia = np.fromiter((p[0] for p in pairs), dtype=np.int64, count=len(pairs))
        self.ib = np.fromiter((p[1] for p in pairs), dtype=np.int64, count=len(pairs))
        self.radii = np.array([s.radius for s in self.solids], dtype=float)
        self.pair_radii = self.radii[self.ia] + self.radii[self.ib] if len(pairs) else np.zeros(0)
        self.levers = self._levers()
        self._excused: dict[tuple[Any, ...], NDArray[np.bool_]] = {}  # work -> its mask (work recurs: the same holes)

    def __len__(self) -> int:
        return len(self.ia)

    # ------------------------------------------------------------------ placing
    def place(self, q: NDArray[np.float64], only: NDArray[np.int64] | None = None) -> list[Matrix]:
        """Every solid's pose in the world at joint vector ``q`` (``only``: just those, the rest left as None)."""
        scene = self.scene
        scene.place(q)
        out: list[Any] = [None] * len(self.attach)
        oMg, oMf = scene.gdata.oMg, scene.data.oMf
        for i in range(len(self.attach)) if only is None else only.tolist():
            kind, where = self.attach[i]
            if kind == "link":
                out[i] = oMg[where].homogeneous
            elif kind == "tcp":
                frame, offset = where
                out[i] = oMf[frame].homogeneous @ offset
            else:
                out[i] = where
        return out

    # ------------------------------------------------------------------ work
    def excluded(self, work: Mapping[str, Sequence[Pose]]) -> NDArray[np.bool_]:
        """Pairs where an arm's end effector touches the box it works on (within the work reach of where
        its motion starts or ends): allowed contact, not measured."""
        mask = np.zeros(len(self.ia), dtype=bool)
        if not work or len(self.boxes) == 0:
            return mask
        key = tuple(sorted((group, tuple(targets)) for group, targets in work.items()))
        known = self._excused.get(key)
        if known is not None:
            return known.copy()
        working: set[tuple[str, int]] = set()
        for group, targets in work.items():
            for target in targets:
                point = np.asarray(target.position, dtype=float)
                for k, (matrix, size) in enumerate(self.boxes):
                    local = matrix[:3, :3].T @ (point - matrix[:3, 3])
                    outside = np.maximum(np.abs(local) - 0.5 * np.asarray(size), 0.0)
                    if float(np.linalg.norm(outside)) <= self.work_reach:
                        working.add((group, self.box_start + k))
        for n, (i, k) in enumerate(zip(self.ia.tolist(), self.ib.tolist())) if working else ():
            a, b = self.solids[i].body, self.solids[k].body
            mask[n] = (a.end_effector and (a.group, k) in working) or (b.end_effector and (b.group, i) in working)
        if len(self._excused) < 256:  # an arm's work changes once per motion; a few hundred states at most recur
            self._excused[key] = mask.copy()
        return mask

    # ------------------------------------------------------------------ levers
    def _levers(self) -> NDArray[np.float64]:
        """(pairs x joints) m of a pair's distance per rad of each joint (see the module docstring)."""
        model = self.scene.model
        nq = model.nq
        placements = [np.linalg.norm(model.jointPlacements[j].translation) for j in range(model.njoints)]
        per_solid = np.zeros((len(self.solids), nq))
        chains: list[set[int]] = []
        for s, solid in enumerate(self.solids):
            joint, reach, chain = int(solid.joint), float(np.linalg.norm(solid.centre)) + solid.radius, set()
            while joint > 0:
                chain.add(joint)
                per_solid[s, model.joints[joint].idx_q] = reach
                reach += placements[joint]
                joint = int(model.parents[joint])
            chains.append(chain)
        levers = np.zeros((len(self.ia), nq))
        q_of = {j: model.joints[j].idx_q for j in range(1, model.njoints)}
        for n, (i, k) in enumerate(zip(self.ia.tolist(), self.ib.tolist())):
            for j in chains[i] ^ chains[k]:  # a joint carrying both moves them as one
                levers[n, q_of[j]] = per_solid[i, q_of[j]] + per_solid[k, q_of[j]]
        return levers


