"""Collision checking of a robot and its cell with coal, through pinocchio's GeometryModel.

The robot's collision geometry is the ``<collision>`` of each link of its URDF (boxes, and
cylinders read as capsules of the same radius and length -- URDF has no capsule, and a capsule's
distance is exact and cheap); pinocchio places it for a joint vector and coal measures the
distance between each pair of bodies that can meet:

* arm against arm (the two arms of a Nextage, with their hands, tools and held parts),
* arm against the rest of the robot (torso, head, base), except the links next to the arm's
  mount: links at most :data:`NEIGHBOUR_JOINTS` joints apart touch by construction,
* every moving body against the cell's boxes (fixtures, parts, trays).

A pair closer than the margin (default :data:`DEFAULT_MARGIN`) is a :class:`Contact`: a
collision when the bodies touch or overlap, a near miss otherwise.  Work is contact: while an
arm's current motion ends within :data:`WORK_REACH` of a cell box (it deburs, inserts, picks
there), its hand, tool and held part may touch that box; the rest of the arm may not.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

try:
    import coal
except ImportError:  # pinocchio before 3.0 ships coal under its former name: ROS 2 Jazzy's numpy 1.26 needs pin 2.7
    import hppfcl as coal  # type: ignore[no-redef]
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from core_functions.urdf_tree import parent_joint
from robot_bridges.collision.bodies import CellBox, HeldPart
from robot_bridges.collision.layout import Layout

Vector = NDArray[np.float64]
_Transform = getattr(coal, "Transform3s", None) or coal.Transform3f  # hpp-fcl's name for it

#: Distance every pair of bodies keeps, unless a function works there (m): the stated margin.
DEFAULT_MARGIN = 0.01
#: An arm whose motion ends this close to a cell box works on it (m).
WORK_REACH = 0.02
#: Links this many joints apart or fewer are neighbours on the robot and are not checked.
NEIGHBOUR_JOINTS = 2
STATIC = "body"  # the group of links no joint of a group moves (a robot's base)
_CELL = "cell"


@dataclass(frozen=True)
class Body:
    """One solid: who it belongs to (a group, ``body`` for the robot's fixed base, ``cell``) and its name."""

    group: str
    name: str
    end_effector: bool = False  # a hand, tool or held part: may touch the work

    def label(self) -> str:
        if self.group == _CELL:
            return f"cell {self.name}"
        if self.group == STATIC:
            return f"robot {self.name}"
        if self.end_effector and self.name.endswith("_Link") or self.name in ("flange", "tool0", "link_6"):
            return f"{self.group} hand ({self.name})"
        return f"{self.group} {self.name}"


@dataclass(frozen=True)
class Contact:
    """Two bodies closer than the margin; ``distance`` <= 0 is a collision, otherwise a near miss."""

    a: Body
    b: Body
    distance: float

    @property
    def collision(self) -> bool:
        return self.distance <= 0.0

    def describe(self, margin: float) -> str:
        if self.collision:
            return f"collision between {self.a.label()} and {self.b.label()}"
        return f"collision margin: {self.a.label()} and {self.b.label()} {self.distance * 1000:.1f} mm apart, below the {margin * 1000:.0f} mm safety margin"


@dataclass(frozen=True)
class ArmTcp:
    """Where an arm's TCP is: a frame of the URDF and the tool pose in it (z out of the tool)."""

    frame: str
    tool: Pose = Pose()


class Solid:
    """A coal geometry with a bounding sphere (for the broad phase) and where it hangs on the robot.

    ``joint`` is the pinocchio joint that carries it (0: the world) and ``centre`` the sphere's
    centre in that joint's frame: what the levers of conservative advancement are measured from.
    """

    def __init__(self, body: Body, geometry: coal.CollisionGeometry, radius: float, joint: int = 0, centre: Vector | None = None) -> None:
        self.body = body
        self.geometry = geometry
        self.radius = radius
        self.joint = joint
        self.centre = np.zeros(3) if centre is None else centre


def _box_radius(size: Sequence[float]) -> float:
    return 0.5 * float(np.linalg.norm(size))


def transform(m: NDArray[np.float64]) -> Any:
    """A 4x4 pose as coal's transform."""
    return _Transform(np.ascontiguousarray(m[:3, :3]), np.ascontiguousarray(m[:3, 3]))


class CollisionScene:
    """A robot's collision model from its URDF; the cell and held parts are set as they change."""

    def __init__(self, robot: RobotModel, urdf: Path | str, tcps: Mapping[str, ArmTcp], margin: float = DEFAULT_MARGIN) -> None:
        if not margin >= 0.0:
            raise ValueError(f"collision margin must be a distance >= 0 m, got {margin!r}")
        self.robot = robot
        self.margin = float(margin)
        self.model = pin.buildModelFromUrdf(str(urdf))
        self.geom = pin.buildGeomFromUrdf(self.model, str(urdf), pin.GeometryType.COLLISION)
        self.data = self.model.createData()
        self.gdata = pin.GeometryData(self.geom)
        #: The model's joint order (pinocchio's): what :meth:`contacts` takes.
        self.joint_names = tuple(self.model.names[j] for j in range(1, self.model.njoints))
        owner = {j: g.name for g in robot.groups for j in g.joint_names}
        self._links: list[Solid] = []
        self._link_joint: list[int] = []
        for obj in self.geom.geometryObjects:
            link = self.model.frames[obj.parentFrame].name
            group = owner.get(self.model.names[obj.parentJoint], STATIC) if obj.parentJoint > 0 else STATIC
            shape = obj.geometry
            if isinstance(shape, coal.Cylinder):  # URDF has no capsule: the cylinder with round ends
                shape = coal.Capsule(shape.radius, 2.0 * shape.halfLength)
                radius = shape.halfLength + shape.radius
            elif isinstance(shape, coal.Box):
                radius = _box_radius(2.0 * np.asarray(shape.halfSide))
            elif isinstance(shape, coal.Sphere):
                radius = shape.radius
            else:
                raise ValueError(f"{urdf}: collision geometry of {link} must be a box, cylinder or sphere, not {type(shape).__name__}")
            tcp = tcps.get(group)
            body = Body(group, link, tcp is not None and tcp.frame == link)
            self._links.append(Solid(body, shape, radius, obj.parentJoint, np.array(obj.placement.translation, dtype=float)))
            self._link_joint.append(obj.parentJoint)
        self.tcps = dict(tcps)
        self._tcp_frame = {g: self.model.getFrameId(t.frame) for g, t in self.tcps.items()}
        self._tools: dict[str, Solid] = {}
        for group, tcp in self.tcps.items():
            self.set_tool(group, tcp.tool)
        self._held: dict[str, tuple[HeldPart, Solid]] = {}
        self._boxes: list[tuple[CellBox, Solid, NDArray[np.float64]]] = []
        self._link_pairs = self._robot_pairs()
        self._layout: Layout | None = None
        self._layouts: dict[tuple[Any, ...], Layout] = {}  # (tools, held parts) -> its layout: they recur (pick, insert, let go)

    # ------------------------------------------------------------------ what is in the scene
    def set_tool(self, group: str, tool: Pose) -> None:
        """The arm's TCP in its frame; a tool longer than 5 mm is a capsule from the flange to the TCP."""
        self.tcps[group] = ArmTcp(self.tcps[group].frame, tool)
        self._layout = None
        length = float(np.linalg.norm(tool.position))
        if length > 0.005:
            self._tools[group] = Solid(Body(group, "tool", True), coal.Capsule(0.015, length), 0.5 * length + 0.015)
        else:
            self._tools.pop(group, None)

    def set_cell(self, boxes: Sequence[CellBox]) -> None:
        self._layout = None
        self._layouts.clear()
        self._boxes = [(box, Solid(Body(_CELL, box.frame), coal.Box(*box.size), _box_radius(box.size)), box.pose.matrix()) for box in boxes]

    def set_held(self, group: str, part: HeldPart | None) -> None:
        """What the arm's gripper holds now (None: nothing)."""
        self._layout = None
        if part is None:
            self._held.pop(group, None)
            return
        solid = Solid(Body(group, f"held {part.element}", True), coal.Capsule(part.radius, part.length), 0.5 * part.length + part.radius)
        self._held[group] = (part, solid)

    def held(self, group: str) -> HeldPart | None:
        entry = self._held.get(group)
        return None if entry is None else entry[0]

    @property
    def boxes(self) -> tuple[CellBox, ...]:
        return tuple(b for b, _, _ in self._boxes)

    def _robot_pairs(self) -> list[tuple[int, int]]:
        """Link pairs of different groups, not neighbours on the robot, not both fixed."""
        parents = self.model.parents

        def chain(j: int) -> list[int]:
            out = [j]
            while j > 0:
                j = parents[j]
                out.append(j)
            return out

        pairs = []
        for i, a in enumerate(self._links):
            for k in range(i + 1, len(self._links)):
                b = self._links[k]
                if a.body.group == b.body.group or STATIC == a.body.group == b.body.group:
                    continue
                ca, cb = chain(self._link_joint[i]), chain(self._link_joint[k])
                common = next(j for j in ca if j in cb)
                if ca.index(common) + cb.index(common) <= NEIGHBOUR_JOINTS:
                    continue
                pairs.append((i, k))
        return pairs

    # ------------------------------------------------------------------ the check
    def tcp_matrix(self, group: str) -> NDArray[np.float64]:
        """The TCP of ``group`` at the configuration of the last :meth:`place`."""
        frame = self.data.oMf[self._tcp_frame[group]]
        return frame.homogeneous @ self.tcps[group].tool.matrix()

    def place(self, q: Vector) -> None:
        """Put every link where joint vector ``q`` (:attr:`joint_names` order) puts it."""
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, q)
        pin.updateFramePlacements(self.model, self.data)

    def layout(self) -> Layout:
        """The scene's solids, pairs and levers as it is now (built once per change of tool, held part or cell)."""
        if self._layout is None:
            key = (tuple(t.tool for t in self.tcps.values()), tuple(sorted((g, part) for g, (part, _) in self._held.items())))
            known = self._layouts.get(key)
            if known is None:
                known = self._build_layout()
                if len(self._layouts) < 64:
                    self._layouts[key] = known
            self._layout = known
        return self._layout

    def _build_layout(self) -> Layout:
        solids: list[Solid] = list(self._links)
        attach: list[tuple[str, Any]] = [("link", i) for i in range(len(self._links))]
        extra: list[int] = []
        for group in self.tcps:
            frame = self.model.frames[self._tcp_frame[group]]
            tool = self.tcps[group].tool.matrix()
            hung: list[tuple[Solid, NDArray[np.float64]]] = []
            solid = self._tools.get(group)
            if solid is not None:
                back = np.eye(4)
                back[2, 3] = -0.5 * float(np.linalg.norm(self.tcps[group].tool.position))
                hung.append((solid, tool @ back))
            held = self._held.get(group)
            if held is not None:
                part, solid = held
                along = np.eye(4)
                along[2, 3] = 0.5 * (part.tip - part.top)
                hung.append((solid, tool @ along))
            for solid, offset in hung:
                solid.joint = parent_joint(frame)  # pinocchio 3 and 2 (ROS 2 Jazzy's 2.7)
                solid.centre = np.asarray((frame.placement.homogeneous @ offset)[:3, 3], dtype=float)
                extra.append(len(solids))
                solids.append(solid)
                attach.append(("tcp", (self._tcp_frame[group], offset)))
        box_start = len(solids)
        for _, solid, matrix in self._boxes:
            solids.append(solid)
            attach.append(("fixed", matrix))
        pairs = list(self._link_pairs)
        for e in extra:  # tools and held parts against everything not of their own group
            group = solids[e].body.group
            pairs += [(i, e) for i in range(box_start) if i != e and solids[i].body.group != group]
        movers = [i for i in range(box_start) if solids[i].body.group != STATIC]
        pairs += [(i, b) for i in movers for b in range(box_start, len(solids))]
        boxes = [(matrix, box.size) for box, _, matrix in self._boxes]
        return Layout(self, solids, attach, box_start, pairs, boxes, WORK_REACH)

    def contacts(self, q: Vector, work: Mapping[str, Sequence[Pose]] | None = None) -> list[Contact]:
        """Every pair of bodies closer than the margin at ``q``, closest pair of each body pair.

        ``work`` maps an arm to where its current motion starts and ends (its TCP there): the arm
        works on the cell boxes within :data:`WORK_REACH` of either point (going in, coming out).
        """
        layout = self.layout()
        if not len(layout):
            return []
        placements = layout.place(q)
        centres = np.array([p[:3, 3] for p in placements])
        gaps = np.linalg.norm(centres[layout.ia] - centres[layout.ib], axis=1) - layout.pair_radii
        near = np.nonzero((gaps < self.margin) & ~layout.excluded(work or {}))[0]
        found = []
        for n in near.tolist():
            i, k = int(layout.ia[n]), int(layout.ib[n])
            distance = self.distance(layout.solids[i], placements[i], layout.solids[k], placements[k])
            if distance < self.margin:
                found.append(Contact(layout.solids[i].body, layout.solids[k].body, distance))
        return found

    @staticmethod
    def distance(a: Solid, at_a: NDArray[np.float64], b: Solid, at_b: NDArray[np.float64]) -> float:
        """coal's distance between two solids at their poses (negative: how deep they overlap)."""
        return float(coal.distance(a.geometry, transform(at_a), b.geometry, transform(at_b), coal.DistanceRequest(), coal.DistanceResult()))
