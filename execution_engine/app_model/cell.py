"""The cell model: the paper's fixture and element information, as one tree of named frames.

Herrero et al. keep what changes between scenarios -- where the holes of a part are, which rivet
goes where -- out of the skills, in XML files extracted from CAD; skills take names and look the
poses up.  A :class:`Cell` is that lookup: frames composed down the tree into the world frame
(the robot base), the elements (references) and named joint poses.  An optional ``<actual>`` per
frame says where the thing really is, so the simulated vision has something to find.

A cell can be loaded before the robot is known; :func:`check_joint_poses` checks its joint poses
once an application names the robot.
"""
from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

from lxml import etree

from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from execution_engine.app_model.diagnostics import ApplicationError, Diagnostic, Location, has_errors, sorted_diagnostics
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, XmlDocument
from execution_engine.app_model.schema import read_structured
from core_functions.cell_index import CellFrame
from execution_engine.transport.wire import CellSnapshot

WORLD = "world"
_LENGTH = {"m": 1.0, "mm": 1e-3}
_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
_FRAME_ATTRIBUTES = ("name", "parent", "xyz", "rpy", "kind")
_ELEMENT_ATTRIBUTES = ("name", "kind")

LengthUnit = Literal["m", "mm"]
AngleUnit = Literal["rad", "deg"]


@dataclass(frozen=True)
class Frame:
    """A named frame: its pose in its parent (SI units), its kind and free attributes."""

    name: str
    parent: str = WORLD
    local: Pose = Pose()
    kind: str = "frame"
    attributes: Mapping[str, str] = field(default_factory=dict)
    actual: Pose | None = None  # the true pose relative to the nominal one (simulated vision)
    location: Location | None = None


@dataclass(frozen=True)
class Element:
    """A reference (a rivet type, a part) with its free attributes, as written."""

    name: str
    kind: str = "element"
    attributes: Mapping[str, str] = field(default_factory=dict)
    location: Location | None = None


@dataclass(frozen=True)
class JointPose:
    """Named joint values (rad) for one group, or for the whole robot in RobotModel.joint_names order."""

    name: str
    values: tuple[float, ...]
    group: str | None = None
    location: Location | None = None
    joints_location: Location | None = None
    group_location: Location | None = None


@dataclass(frozen=True)
class Cell:
    """A cell model; implements core_functions.catalog.CellView.  ``robot`` is set by :meth:`bind`."""

    name: str
    frames: Mapping[str, Frame] = field(default_factory=dict)
    elements: Mapping[str, Element] = field(default_factory=dict)
    joint_poses: Mapping[str, JointPose] = field(default_factory=dict)
    path: Path | None = None
    robot: RobotModel | None = None
    _world: dict[str, Pose] = field(default_factory=dict, init=False, repr=False, compare=False)
    _truth: dict[str, Pose] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        world, truth = _resolve(self.frames)
        object.__setattr__(self, "_world", world)
        object.__setattr__(self, "_truth", truth)

    # ------------------------------------------------------------------ CellView
    def has_frame(self, name: str) -> bool:
        return name == WORLD or name in self.frames

    def frame_kind(self, name: str) -> str:
        return WORLD if name == WORLD else self.frames[name].kind

    def frame_names(self) -> Iterable[str]:
        return self.frames.keys()

    def has_element(self, name: str) -> bool:
        return name in self.elements

    def element_kind(self, name: str) -> str:
        return self.elements[name].kind

    def joint_pose_group(self, name: str) -> str | None:
        """The group a joint pose was made for, or None for a whole-robot pose."""
        return self.joint_poses[name].group

    def has_joint_pose(self, name: str) -> bool:
        return name in self.joint_poses

    # ------------------------------------------------------------------ look-ups
    def frame(self, name: str) -> Frame:
        return self.frames[name]

    def element(self, name: str) -> Element:
        return self.elements[name]

    def joint_pose(self, name: str) -> JointPose:
        return self.joint_poses[name]

    def pose(self, name: str) -> Pose:
        """The nominal pose of frame ``name`` in the world frame (KeyError if unknown)."""
        if name == WORLD:
            return Pose()
        return self._world[name]

    def true_pose(self, name: str) -> Pose:
        """Where frame ``name`` really is: its nominal pose corrected by every ``<actual>`` up the chain."""
        return self._truth.get(name) or self.pose(name)

    def bind(self, robot: RobotModel) -> Cell:
        """This cell for ``robot`` (joint poses can then be given by joint name)."""
        return replace(self, robot=robot)

    def joint_values(self, name: str, robot: RobotModel | None = None) -> dict[str, float]:
        """The named joint pose as ``{joint name: rad}`` for ``robot`` (default: the bound robot)."""
        robot = robot or self.robot
        if robot is None:
            raise ValueError(f"cell {self.name}: joint pose {name!r} needs a robot to name its joints")
        pose = self.joint_poses[name]
        names = robot.group(pose.group).joint_names if pose.group else robot.joint_names
        if len(names) != len(pose.values):
            raise ValueError(f"joint pose {name!r} has {len(pose.values)} values; {robot.name} needs {len(names)}")
        return dict(zip(names, pose.values))

    def to_snapshot(self, robot: RobotModel | None = None) -> CellSnapshot:
        """The cell as the engine publishes it: frames in the world, elements, joint poses, truth."""
        frames = tuple(
            CellFrame(name=f.name, pose=self._world[f.name], kind=f.kind, parent=f.parent, attributes=dict(f.attributes))
            for f in self.frames.values()
        )
        elements = {e.name: {"kind": e.kind, **e.attributes} for e in self.elements.values()}
        joint_poses = {name: self.joint_values(name, robot) for name in self.joint_poses}
        groups = {name: pose.group for name, pose in self.joint_poses.items() if pose.group}
        return CellSnapshot(
            name=self.name, frames=frames, elements=elements, joint_poses=joint_poses, truth=dict(self._truth), joint_pose_groups=groups
        )


def _resolve(frames: Mapping[str, Frame]) -> tuple[dict[str, Pose], dict[str, Pose]]:
    """World poses (and true poses where an ``actual`` applies) of every frame, parents first."""
    world: dict[str, Pose] = {}
    truth: dict[str, Pose] = {}
    for name in frames:
        chain: list[Frame] = []
        current = name
        while current != WORLD and current not in world:
            if current not in frames:
                raise ValueError(f"frame {chain[-1].name!r} has an unknown parent {current!r}")
            frame = frames[current]
            if any(f.name == current for f in chain):
                raise ValueError(f"frames {' -> '.join(f.name for f in chain)} -> {current} form a cycle")
            chain.append(frame)
            current = frame.parent
        for frame in reversed(chain):
            parent_world = world.get(frame.parent, Pose())
            world[frame.name] = parent_world.compose(frame.local)
            parent_true = truth.get(frame.parent)
            if frame.actual is not None or parent_true is not None:
                base = (parent_true or parent_world).compose(frame.local)
                truth[frame.name] = base.compose(frame.actual) if frame.actual is not None else base
    return world, truth


# ====================================================================== loading
@dataclass
class _FrameDraft:
    frame: Frame
    element: etree._Element
    nested: bool


class _CellReader:
    """Turns a schema-checked (or not) document into a Cell, reporting what the schema cannot see."""

    def __init__(self, doc: XmlDocument) -> None:
        self.doc = doc
        self.diagnostics: list[Diagnostic] = []
        root = doc.root
        self.length = _LENGTH.get(root.get("length_unit", "m"), 1.0)
        self.angle_unit = root.get("angle_unit", "rad")
        self.angle = _ANGLE.get(self.angle_unit, 1.0)

    def error(self, where: Location, message: str) -> None:
        self.diagnostics.append(Diagnostic.at(where, message))

    def attr(self, element: etree._Element, name: str) -> Location:
        return self.doc.source.attribute(element, name)

    def vector(self, element: etree._Element, name: str, scale: float) -> tuple[float, float, float] | None:
        text = element.get(name)
        if text is None:
            return (0.0, 0.0, 0.0)
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            return None  # the schema reports it
        if len(values) != 3:
            return None
        if not all(math.isfinite(v) for v in values):
            self.error(self.attr(element, name), f"{name} of <{element.tag}> must be finite numbers, got {text!r}")
            return None
        return (values[0] * scale, values[1] * scale, values[2] * scale)

    def pose(self, element: etree._Element) -> Pose | None:
        xyz = self.vector(element, "xyz", self.length)
        rpy = self.vector(element, "rpy", self.angle)
        if xyz is None or rpy is None:
            return None
        return Pose.from_xyz_rpy(*xyz, *rpy)

    def free_attributes(self, element: etree._Element, known: tuple[str, ...]) -> dict[str, str]:
        free: dict[str, str] = {}
        for key, value in element.attrib.items():
            if not isinstance(key, str) or not isinstance(value, str) or key in known or key.startswith("{"):
                continue
            free[key] = value
            lookalike = next((k for k in known if _one_edit_apart(key, k)), None)
            if lookalike is not None:
                self.diagnostics.append(
                    Diagnostic.at(
                        self.attr(element, key),
                        f"attribute {key} of <{element.tag}> {element.get('name', '')!r} is kept as a free attribute; "
                        f"did you mean {lookalike}?",
                        "warning",
                    )
                )
        return free

    # ------------------------------------------------------------------ the tree
    def read(self, structure_ok: bool) -> Cell | None:
        """The cell, or None when this reader or the schema (``structure_ok`` False) found errors."""
        drafts: dict[str, _FrameDraft] = {}
        elements: dict[str, Element] = {}
        joint_poses: dict[str, JointPose] = {}
        for child in self.doc.root.iterchildren(etree.Element):
            if child.tag == "frame":
                self.read_frame(child, None, drafts)
            elif child.tag == "element":
                self.read_element(child, elements)
            elif child.tag == "joint_pose":
                self.read_joint_pose(child, joint_poses)
        frames = self.check_tree(drafts)
        self.check_element_references(drafts, elements)
        if has_errors(self.diagnostics) or frames is None or not structure_ok:
            return None
        try:
            return Cell(
                name=self.doc.root.get("name", ""), frames=frames, elements=elements,
                joint_poses=joint_poses, path=self.doc.path,
            )
        except ValueError as error:  # the checks above should make this unreachable
            self.error(self.doc.source.element(self.doc.root), str(error))
            return None

    def read_frame(self, element: etree._Element, enclosing: str | None, drafts: dict[str, _FrameDraft]) -> None:
        """Record the frame, then its children, so frames stay in document order (parents first)."""
        name = element.get("name")
        parent = element.get("parent")
        if enclosing is not None and parent is not None:
            self.error(self.attr(element, "parent"), f"frame {name!r} is inside frame {enclosing!r}: only top-level frames take a parent attribute")
        actuals = list(element.iterchildren("actual"))
        for extra in actuals[1:]:
            self.error(self.doc.source.element(extra), f"frame {name!r} has more than one <actual>")
        local = self.pose(element)
        actual = self.pose(actuals[0]) if actuals else None
        if name and self.register_frame(element, name, enclosing, parent, local, actual, drafts):
            children_parent: str | None = name
        else:
            children_parent = name or "?"  # still read the children, so their own problems show
        for child in element.iterchildren("frame"):
            self.read_frame(child, children_parent, drafts)

    def register_frame(
        self, element: etree._Element, name: str, enclosing: str | None, parent: str | None,
        local: Pose | None, actual: Pose | None, drafts: dict[str, _FrameDraft],
    ) -> bool:
        if name == WORLD:
            self.error(self.attr(element, "name"), f"{WORLD!r} is the robot base frame and cannot be redefined")
            return False
        if name in drafts:
            first = drafts[name].frame.location
            self.error(self.attr(element, "name"), f"frame {name!r} is defined twice (first on line {first.line if first else '?'})")
            return False
        frame = Frame(
            name=name,
            parent=enclosing if enclosing is not None else (parent or WORLD),
            local=local or Pose(),
            kind=element.get("kind", "frame"),
            attributes=self.free_attributes(element, _FRAME_ATTRIBUTES),
            actual=actual,
            location=self.doc.source.element(element),
        )
        drafts[name] = _FrameDraft(frame, element, enclosing is not None)
        return True

    def check_tree(self, drafts: dict[str, _FrameDraft]) -> dict[str, Frame] | None:
        """Known parents first (an unknown one is the thing to fix), then cycles."""
        ok = True
        for draft in drafts.values():
            parent = draft.frame.parent
            if parent != WORLD and parent not in drafts and not draft.nested:
                close = difflib.get_close_matches(parent, [WORLD, *drafts], n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                self.error(self.attr(draft.element, "parent"), f"frame {draft.frame.name!r}: unknown parent frame {parent!r}{hint}")
                ok = False
        if not ok:
            return None
        reported: set[str] = set()
        for name, draft in drafts.items():
            seen: list[str] = []
            current = name
            while current != WORLD and current in drafts and current not in seen:
                seen.append(current)
                current = drafts[current].frame.parent
            if current != WORLD and current == name and name not in reported:
                reported.update(seen)
                self.error(self.attr(draft.element, "parent"), f"frames {' -> '.join(seen)} -> {name} form a cycle: a frame cannot be its own ancestor")
                ok = False
        return {name: d.frame for name, d in drafts.items()} if ok else None

    def check_element_references(self, drafts: dict[str, _FrameDraft], elements: dict[str, Element]) -> None:
        for draft in drafts.values():
            ref = draft.frame.attributes.get("element")
            if ref is not None and ref not in elements:
                self.error(self.attr(draft.element, "element"), f"frame {draft.frame.name!r} names element {ref!r}, which the cell does not define")

    def read_element(self, element: etree._Element, elements: dict[str, Element]) -> None:
        name = element.get("name")
        if not name:
            return
        where = self.doc.source.element(element)
        if name in elements:
            first = elements[name].location
            self.error(self.attr(element, "name"), f"element {name!r} is defined twice (first on line {first.line if first else '?'})")
            return
        elements[name] = Element(name, element.get("kind", "element"), self.free_attributes(element, _ELEMENT_ATTRIBUTES), where)

    def read_joint_pose(self, element: etree._Element, poses: dict[str, JointPose]) -> None:
        name = element.get("name")
        text = element.get("joints")
        if not name or text is None:
            return
        scale = _ANGLE.get(element.get("unit", self.angle_unit), 1.0)
        try:
            values = tuple(float(v) * scale for v in text.split())
        except ValueError:
            return
        if not all(math.isfinite(v) for v in values):
            self.error(self.attr(element, "joints"), f"joint pose {name!r}: joint values must be finite numbers")
            return
        if name in poses:
            first = poses[name].location
            self.error(self.attr(element, "name"), f"joint pose {name!r} is defined twice (first on line {first.line if first else '?'})")
            return
        group = element.get("group")
        poses[name] = JointPose(
            name, values, group, self.doc.source.element(element), self.attr(element, "joints"),
            self.attr(element, "group") if group is not None else None,
        )


def _one_edit_apart(a: str, b: str) -> bool:
    """A likely typo: the same letters reordered, or one letter added, dropped or changed."""
    if a == b or min(len(a), len(b)) < 3:
        return False
    if sorted(a) == sorted(b):
        return True
    if abs(len(a) - len(b)) > 1:
        return False
    if len(a) == len(b):
        return sum(x != y for x, y in zip(a, b)) == 1
    short, long_ = (a, b) if len(a) < len(b) else (b, a)
    return any(long_[:i] + long_[i + 1:] == short for i in range(len(long_)))


# ====================================================================== API
def read_cell(path: Path, *, display: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[Cell | None, list[Diagnostic]]:
    """The cell at ``path`` (None when it has errors) and every diagnostic, sorted."""
    doc, diagnostics = read_structured(Path(path), "cell", display=display, max_bytes=max_bytes)
    if doc is None:
        return None, sorted_diagnostics(diagnostics)
    reader = _CellReader(doc)
    cell = reader.read(structure_ok=not has_errors(diagnostics))
    diagnostics = sorted_diagnostics([*diagnostics, *reader.diagnostics])
    return (cell if not has_errors(diagnostics) else None), diagnostics


def load_cell(path: Path | str, *, max_bytes: int = DEFAULT_MAX_BYTES) -> Cell:
    """The cell at ``path``; ApplicationError with every problem if it is not valid."""
    cell, diagnostics = read_cell(Path(path), max_bytes=max_bytes)
    if cell is None:
        raise ApplicationError(diagnostics)
    return cell


def validate_cell(path: Path | str, robot: RobotModel | None = None, *, max_bytes: int = DEFAULT_MAX_BYTES) -> list[Diagnostic]:
    """Every problem of the cell file; joint poses are checked too when ``robot`` is given."""
    cell, diagnostics = read_cell(Path(path), max_bytes=max_bytes)
    if cell is not None and robot is not None:
        diagnostics = sorted_diagnostics([*diagnostics, *check_joint_poses(cell, robot)])
    return diagnostics


def check_joint_poses(cell: Cell, robot: RobotModel) -> list[Diagnostic]:
    """Each joint pose fits ``robot``: a known group, one value per joint, inside the limits."""
    out: list[Diagnostic] = []
    for pose in cell.joint_poses.values():
        where = pose.joints_location or pose.location or Location(str(cell.path or cell.name), 1, 1)
        if pose.name in robot.poses:
            out.append(Diagnostic.at(pose.location or where, (
                f"joint pose {pose.name!r} has the name of a pose of {robot.name}; the name is ambiguous, rename it"
            ), "warning"))
        if pose.group is not None and pose.group not in robot.group_names:
            group_where = pose.group_location or pose.location or where
            out.append(Diagnostic.at(group_where, f"joint pose {pose.name!r}: {pose.group!r} is not a group of {robot.name} ({', '.join(robot.group_names)})"))
            continue
        joints = robot.group(pose.group).joints if pose.group else robot.joints
        owner = pose.group or robot.name
        if len(pose.values) != len(joints):
            out.append(Diagnostic.at(where, (
                f"joint pose {pose.name!r} has {len(pose.values)} values; {owner} has {len(joints)} joints, "
                f"in this order: {' '.join(j.name for j in joints)}"
            )))
            continue
        for joint, value in zip(joints, pose.values):
            if not joint.contains(value):
                out.append(Diagnostic.at(where, (
                    f"joint pose {pose.name!r}: {joint.name} = {math.degrees(value):.2f} deg is outside its limits "
                    f"[{math.degrees(joint.lower):.1f}, {math.degrees(joint.upper):.1f}] deg"
                )))
    return out
