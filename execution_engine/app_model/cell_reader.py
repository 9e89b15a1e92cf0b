"""Read a cell model file into a :class:`Cell`, reporting what its schema cannot see.

The reader runs after the schema check whatever its outcome, so what it cannot interpret it
skips (the schema says why).  It reports what only the whole file shows -- names defined twice,
unknown parents, cycles, element references -- and what no type can say: numbers that are
floats but not places in a cell (core_functions.limits), each at the attribute that holds them,
in the unit the file uses.

Like the application reader it visits every element once, in document order, so positions come
from :class:`DocumentWalk` as plain offsets and no map from elements to offsets is built.  Its
checks are linear in the number of frames: the frame tree is ordered in one look-up per frame
(frame_tree), and 'did you mean' is asked of a sorted index, for the first few unknown names only.
"""
from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field

from lxml import etree

from core_functions import limits
from core_functions.geometry import Pose
from core_functions.suggest import NameIndex, did_you_mean
from core_functions.cell_robots import CellRobot
from execution_engine.app_model.cell_model import Cell, Element, Frame, JointPose
from execution_engine.app_model.cell_robot_reader import read_robot
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, Severity
from execution_engine.app_model.frame_tree import WORLD, order_frames
from execution_engine.app_model.positions import DocumentWalk
from execution_engine.app_model.safe_xml import XmlDocument
from execution_engine.app_model.zones import Zone

_LENGTH = {"m": 1.0, "mm": 1e-3}
_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
_FRAME_ATTRIBUTES = ("name", "parent", "xyz", "rpy", "kind")
_ELEMENT_ATTRIBUTES = ("name", "kind")
_AXES = {"xyz": ("x", "y", "z"), "rpy": ("roll", "pitch", "yaw")}
_NUMBER = re.compile(r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*")
_ZERO = (0.0, 0.0, 0.0)
_IDENTITY = Pose()
#: Unknown parent names that get a 'did you mean'; the rest are reported without one.
MAX_SUGGESTIONS = 20


@dataclass
class _FrameDraft:
    """A frame as read, before the tree is known to be sound; ``at`` is the offset of its tag."""

    name: str
    parent: str
    local: Pose
    kind: str
    attributes: dict[str, str]
    at: int
    nested: bool
    actual: Pose | None = None
    actual_seen: bool = False
    frame: Frame | None = field(default=None, repr=False)


class CellReader:
    """Turns a schema-checked (or not) document into a Cell; problems go to ``log``."""

    def __init__(self, doc: XmlDocument, log: DiagnosticLog) -> None:
        self.doc = doc
        self.source = doc.source
        self.walk = DocumentWalk(doc.source)
        self.log = log
        root = doc.root
        self.length_unit = root.get("length_unit", "m") if root.get("length_unit") in _LENGTH else "m"
        self.angle_unit = root.get("angle_unit", "rad") if root.get("angle_unit") in _ANGLE else "rad"
        self.suggestions_left = MAX_SUGGESTIONS
        self._zone_at: dict[str, int] = {}  # where each zone is written

    # ------------------------------------------------------------------ reporting
    def report(self, at: int, attribute: str | None, message: str, severity: Severity = "error") -> None:
        """A problem at the tag at ``at`` (or its ``attribute``); only counted once the log is full."""
        if self.log.full:
            self.log.count(severity)
            return
        where = self.source.attribute_at(at, attribute) if attribute else self.source.at_offset(at)
        self.log.append(Diagnostic.at(where, message, severity))

    # ------------------------------------------------------------------ numbers
    def vector(self, element: etree._Element, at: int, name: str, label: str) -> tuple[float, float, float] | None:
        """``xyz`` or ``rpy`` in SI units; None when absent-and-wrong (the schema says) or out of bounds."""
        text = element.get(name)
        if text is None:
            return (0.0, 0.0, 0.0)
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            return None  # the schema reports it
        if len(values) != 3:
            return None
        if name == "xyz":
            bound, unit, scale = limits.BY_UNIT["m"], self.length_unit, _LENGTH[self.length_unit]
        else:
            bound, unit, scale = limits.BY_UNIT["rad"], self.angle_unit, _ANGLE[self.angle_unit]
        scaled = (values[0] * scale, values[1] * scale, values[2] * scale)
        if all(bound.lower <= v <= bound.upper for v in scaled):  # false for nan and inf too
            return scaled
        if not all(math.isfinite(v) for v in values):
            self.report(at, name, f"{name} of <{element.tag}> must be finite numbers, got {text!r}")
            return None
        for axis, value in zip(_AXES[name], values):
            problem = bound.violation(axis, value, scale, unit)
            if problem is not None:
                self.report(at, name, f"{name} of <{element.tag}> {label}: {problem}")
                return None
        return scaled  # unreachable: some axis was out of bounds

    def solid(self, element: etree._Element, at: int, attributes: dict[str, str], label: str) -> None:
        """``box`` (side lengths, each > 0) and ``box_xyz`` (its centre in the frame), in the file's
        length unit: checked like ``xyz`` and kept in metres for the collision model."""
        for name in ("box", "box_xyz"):
            text = attributes.get(name)
            if text is None:
                continue
            values = _numbers3(text, finite=False)
            if values is None:  # not three numbers: the schema says so
                del attributes[name]
                continue
            if not all(math.isfinite(v) for v in values):
                self.report(at, name, f"{name} of <{element.tag}> {label} must be finite numbers, got {text!r}")
                del attributes[name]
                continue
            scale = _LENGTH[self.length_unit]
            problem = next((p for axis, v in zip(_AXES["xyz"], values) if (p := limits.LENGTH.violation(axis, v, scale, self.length_unit))), None)
            if problem is None and name == "box" and min(values) <= 0.0:
                problem = f"every side must be longer than 0 {self.length_unit}"
            if problem is not None:
                self.report(at, name, f"{name} of <{element.tag}> {label}: {problem}")
                del attributes[name]
                continue
            attributes[name] = " ".join(repr(v * scale) for v in values)
        if "box_xyz" in attributes and "box" not in attributes:
            self.report(at, "box_xyz", f"box_xyz of <{element.tag}> {label} places a box, but the frame has no box", "warning")

    def pose(self, element: etree._Element, at: int, label: str) -> Pose | None:
        xyz = self.vector(element, at, "xyz", label)
        rpy = self.vector(element, at, "rpy", label)
        if xyz is None or rpy is None:
            return None
        if xyz == _ZERO and rpy == _ZERO:
            return _IDENTITY  # most frames of a generated cell: no need to build and check a pose
        return Pose.from_xyz_rpy(*xyz, *rpy)

    def free_attributes(self, element: etree._Element, at: int, known: tuple[str, ...]) -> dict[str, str]:
        """Attributes kept as text for the skills; numbers among them must at least be finite."""
        free: dict[str, str] = {}
        for key, value in element.attrib.items():
            if not isinstance(key, str) or not isinstance(value, str) or key in known or key.startswith("{"):
                continue
            free[key] = value
            if _NUMBER.fullmatch(value) and not math.isfinite(float(value)):
                self.report(at, key, f"attribute {key}={value.strip()!r} of <{element.tag}> {element.get('name', '')!r} is not a finite number")
            lookalike = next((k for k in known if _one_edit_apart(key, k)), None)
            if lookalike is not None:
                self.report(at, key, (
                    f"attribute {key} of <{element.tag}> {element.get('name', '')!r} is kept as a free attribute; "
                    f"did you mean {lookalike}?"
                ), "warning")
        return free

    # ------------------------------------------------------------------ the tree
    def children(self, element: etree._Element) -> Iterator[tuple[etree._Element, int]]:
        """The element children in document order, each with its offset (the walk visits each:
        a caller not reading one's subtree calls ``self.walk.skip``)."""
        for child in element:
            if isinstance(child.tag, str):
                yield child, self.walk.visit(child)

    def read(self, structure_ok: bool) -> Cell | None:
        """The cell, or None when this reader or the schema (``structure_ok`` False) found errors."""
        root = self.doc.root
        root_at = self.walk.visit(root)
        drafts: dict[str, _FrameDraft] = {}
        elements: dict[str, Element] = {}
        joint_poses: dict[str, JointPose] = {}
        zones: dict[str, Zone] = {}
        robots: list[CellRobot] = []
        robot_lines: dict[str, int] = {}
        for child, at in self.children(root):
            if child.tag == "frame":
                self.read_frame(child, at, None, drafts)
                continue
            if child.tag == "element":
                self.read_element(child, at, elements)
            elif child.tag == "joint_pose":
                self.read_joint_pose(child, at, joint_poses)
            elif child.tag == "zone":
                self.read_zone(child, at, zones)
            elif child.tag == "robot":
                parts: list[tuple[etree._Element, int]] = []  # its <option> and <group>, each where it is written
                for part, part_at in self.children(child):
                    parts.append((part, part_at))
                    self.walk.skip(part)
                read_robot(self, child, at, parts, robots, robot_lines, self.source.at_offset(at).line)
                continue
            self.walk.skip(child)
        frames = self.check_tree(drafts)
        self.check_element_references(drafts, elements)
        for zone in zones.values():
            if zone.name in drafts:  # the machines see zones as frames of the snapshot: one name, one thing
                self.report(self._zone_at[zone.name], "name", f"zone {zone.name!r} has the name of a frame (line {self.source.at_offset(drafts[zone.name].at).line}): name it apart")
            elif zone.parent != WORLD and zone.parent not in drafts:
                self.report(self._zone_at[zone.name], "parent", f"zone {zone.name!r}: unknown parent frame {zone.parent!r}")
        if self.log.has_errors or frames is None or not structure_ok:
            return None
        try:
            return Cell(name=root.get("name", ""), frames=frames, elements=elements, joint_poses=joint_poses, path=self.doc.path, zones=zones, robots=tuple(robots))
        except ValueError as error:  # the checks above should make this unreachable
            self.report(root_at, None, str(error))
            return None

    def read_frame(self, element: etree._Element, at: int, enclosing: str | None, drafts: dict[str, _FrameDraft]) -> None:
        """Record the frame, then its children in document order (parents first)."""
        name = element.get("name")
        parent = element.get("parent")
        if enclosing is not None and parent is not None:
            self.report(at, "parent", f"frame {name!r} is inside frame {enclosing!r}: only top-level frames take a parent attribute")
        local = self.pose(element, at, repr(name or ""))
        draft = self.register_frame(element, at, name, enclosing, parent, local, drafts) if name else None
        children_parent = name if draft is not None else (name or "?")  # still read the children: their own problems show
        for child, child_at in self.children(element):
            if child.tag == "frame":
                self.read_frame(child, child_at, children_parent, drafts)
                continue
            if child.tag == "actual":
                self.read_actual(child, child_at, name, draft)
            self.walk.skip(child)

    def read_actual(self, element: etree._Element, at: int, name: str | None, draft: _FrameDraft | None) -> None:
        if draft is not None and draft.actual_seen:
            self.report(at, None, f"frame {name!r} has more than one <actual>")
            return
        actual = self.pose(element, at, f"of frame {name!r}")
        if draft is not None:
            draft.actual_seen = True
            draft.actual = actual

    def register_frame(
        self, element: etree._Element, at: int, name: str, enclosing: str | None, parent: str | None,
        local: Pose | None, drafts: dict[str, _FrameDraft],
    ) -> _FrameDraft | None:
        if name == WORLD:
            self.report(at, "name", f"{WORLD!r} is the robot base frame and cannot be redefined")
            return None
        if name in drafts:
            first = self.source.line_col(drafts[name].at)[0]
            self.report(at, "name", f"frame {name!r} is defined twice (first on line {first})")
            return None
        attributes = self.free_attributes(element, at, _FRAME_ATTRIBUTES)
        self.solid(element, at, attributes, repr(name))
        draft = _FrameDraft(
            name=name,
            parent=enclosing if enclosing is not None else (parent or WORLD),
            local=local or Pose(),
            kind=element.get("kind", "frame"),
            attributes=attributes,
            at=at,
            nested=enclosing is not None,
        )
        drafts[name] = draft
        return draft

    def check_tree(self, drafts: dict[str, _FrameDraft]) -> dict[str, Frame] | None:
        """Known parents first (an unknown one is the thing to fix), then cycles; linear time."""
        ok = True
        names: NameIndex | None = None
        for draft in drafts.values():
            parent = draft.parent
            if parent == WORLD or parent in drafts or draft.nested:
                continue
            ok = False
            hint = ""
            if self.suggestions_left > 0 and not self.log.full:
                self.suggestions_left -= 1
                names = names or NameIndex([WORLD, *drafts])
                hint = did_you_mean(names.suggest(parent))
            self.report(draft.at, "parent", f"frame {draft.name!r}: unknown parent frame {parent!r}{hint}")
        if not ok:
            return None
        ordered = order_frames({name: d.parent for name, d in drafts.items()})
        for cycle in ordered.cycles:
            chain = " -> ".join(cycle)
            self.report(drafts[cycle[0]].at, "parent", f"frames {chain} -> {cycle[0]} form a cycle: a frame cannot be its own ancestor")
        if ordered.cycles:
            return None
        return {
            name: Frame(
                name=name, parent=d.parent, local=d.local, kind=d.kind, attributes=d.attributes, actual=d.actual,
                location=self.source.at_offset(d.at),
            )
            for name, d in drafts.items()
        }

    def check_element_references(self, drafts: dict[str, _FrameDraft], elements: dict[str, Element]) -> None:
        for draft in drafts.values():
            ref = draft.attributes.get("element")
            if ref is not None and ref not in elements:
                self.report(draft.at, "element", f"frame {draft.name!r} names element {ref!r}, which the cell does not define")

    def read_element(self, element: etree._Element, at: int, elements: dict[str, Element]) -> None:
        name = element.get("name")
        if not name:
            return
        if name in elements:
            first = elements[name].location
            self.report(at, "name", f"element {name!r} is defined twice (first on line {first.line if first else '?'})")
            return
        elements[name] = Element(name, element.get("kind", "element"), self.free_attributes(element, at, _ELEMENT_ATTRIBUTES), self.source.at_offset(at))

    def read_zone(self, element: etree._Element, at: int, zones: dict[str, Zone]) -> None:
        """``<zone name parent xyz size>``: a box in the parent frame, in the file's length unit."""
        name = element.get("name")
        if not name:
            return
        if name in zones:
            self.report(at, "name", f"zone {name!r} is defined twice")
            return
        centre = self.vector(element, at, "xyz", repr(name))
        size = _numbers3(element.get("size", ""), finite=False)
        scale = _LENGTH[self.length_unit]
        if size is None:
            return  # not three numbers: the schema says so
        if not (min(size) > 0 and max(size) * scale <= limits.LENGTH.upper):  # false for nan and inf too
            self.report(at, "size", f"size of <zone> {name!r} must be three side lengths > 0 (x y z, {self.length_unit}), within the bound of a length")
            return
        if centre is None:
            return
        self._zone_at[name] = at
        zones[name] = Zone(name, element.get("parent", WORLD), centre, (size[0] * scale, size[1] * scale, size[2] * scale), self.source.at_offset(at))

    def read_joint_pose(self, element: etree._Element, at: int, poses: dict[str, JointPose]) -> None:
        name = element.get("name")
        text = element.get("joints")
        if not name or text is None:
            return
        unit = element.get("unit", self.angle_unit)
        scale = _ANGLE.get(unit, 1.0)
        try:
            written = [float(v) for v in text.split()]
        except ValueError:
            return
        if not all(math.isfinite(v) for v in written):
            self.report(at, "joints", f"joint pose {name!r}: joint values must be finite numbers")
            return
        for index, value in enumerate(written):
            problem = limits.BY_UNIT["rad"].violation(f"joint {index + 1}", value, scale, unit if unit in _ANGLE else "rad")
            if problem is not None:
                self.report(at, "joints", f"joint pose {name!r}: {problem}")
                return
        if name in poses:
            first = poses[name].location
            self.report(at, "name", f"joint pose {name!r} is defined twice (first on line {first.line if first else '?'})")
            return
        group = element.get("group")
        poses[name] = JointPose(
            name, tuple(v * scale for v in written), group, self.source.at_offset(at), self.source.attribute_at(at, "joints"),
            self.source.attribute_at(at, "group") if group is not None else None,
        )


def _numbers3(text: str, finite: bool = True) -> tuple[float, float, float] | None:
    """Three numbers separated by spaces (finite ones unless ``finite`` is False), or None."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        return None
    if len(values) != 3 or finite and not all(math.isfinite(v) for v in values):
        return None
    return values[0], values[1], values[2]


def _one_edit_apart(a: str, b: str) -> bool:
    """A likely typo: the same letters reordered, or one letter added, dropped or changed."""
    if a == b or min(len(a), len(b)) < 3 or abs(len(a) - len(b)) > 1:
        return False
    if sorted(a) == sorted(b):
        return True
    if len(a) == len(b):
        return sum(x != y for x, y in zip(a, b)) == 1
    short, long_ = (a, b) if len(a) < len(b) else (b, a)
    return any(long_[:i] + long_[i + 1:] == short for i in range(len(long_)))
