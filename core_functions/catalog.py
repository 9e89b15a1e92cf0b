"""The function catalog: every function an application may call, with typed parameters and docs.

Functions are methods of :class:`core_functions.functions.CoreFunctions` and of the app-function
libraries that inherit from it, marked with :func:`skill`.  The catalog is built from those
classes, so what ``python -m execution_engine functions`` lists, what the XML validator accepts
and what a group machine executes cannot disagree.

Parameters arrive as the strings of ``<param value=...>``.  :meth:`FunctionSpec.bind` parses them
-- numbers with optional units (``mm``, ``deg``, ``ms``), joint lists, poses, frame and element
names resolved against the cell model -- and reports each problem with the index of the
parameter, so the validator can point at its line and column.
"""
from __future__ import annotations

import inspect
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Protocol

from core_functions import limits
from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from core_functions.suggest import NameIndex, did_you_mean

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
MAX_PARAM_LENGTH = 4096


class ParamType(Enum):
    """What a parameter holds; the text after each name is what the catalog shows users."""

    NUMBER = "number"  # a real number, with an optional unit suffix of the param's unit family
    INTEGER = "integer"
    BOOLEAN = "boolean"  # true/false, yes/no, 1/0
    TEXT = "text"  # free text (a label, a message)
    CHOICE = "choice"  # one of the listed choices
    NAME = "name"  # an identifier you choose (a trajectory name)
    FRAME = "frame"  # the name of a frame of the cell model
    FRAMES = "frames"  # one or more cell frame names, separated by spaces or commas
    ELEMENT = "element"  # the name of an element (reference) of the cell model
    TARGET = "target"  # a cell frame name, or "x,y,z,roll,pitch,yaw" in m and rad (mm/deg suffix allowed)
    JOINTS = "joints"  # one value per joint of the group, rad (deg suffix allowed)
    JOINT_POSE = "joint_pose"  # a named joint pose of the robot or the cell (initial, off, home, ...)
    GROUP = "group"  # the name of another group of the robot
    CAMERA = "camera"  # a camera of the robot, or auto for the group's own


class Hold(Enum):
    """What a group's hand holds, for the plausibility check across operations (Verl 2008)."""

    NOTHING = "nothing"
    PART = "part"  # some element (a rivet, a part): see the element's kind
    UNKNOWN = "unknown"


# Unit families: the canonical unit and what other suffixes mean in it.
_UNITS: dict[str, dict[str, float]] = {
    "m": {"m": 1.0, "mm": 1e-3, "cm": 1e-2},
    "rad": {"rad": 1.0, "deg": math.pi / 180.0},
    "s": {"s": 1.0, "ms": 1e-3},
    "m/s": {"m/s": 1.0, "mm/s": 1e-3},
    "fraction": {"": 1.0, "%": 0.01},
    "": {"": 1.0},
}
_NUMBER_WITH_UNIT = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z/%]*)\s*$")


class ParamError(ValueError):
    """A parameter value that cannot be used; ``index`` is its position among the params."""

    def __init__(self, index: int | None, message: str) -> None:
        super().__init__(message)
        self.index = index
        self.message = message


class CellView(Protocol):
    """What binding needs of a cell model (implemented by the application model's Cell)."""

    def has_frame(self, name: str) -> bool: ...
    def frame_kind(self, name: str) -> str: ...
    def frame_names(self) -> Iterable[str]: ...
    def has_element(self, name: str) -> bool: ...
    def element_kind(self, name: str) -> str: ...
    def has_joint_pose(self, name: str) -> bool: ...
    def joint_pose_group(self, name: str) -> str | None: ...
    def suggest_frame(self, name: str) -> str | None: ...


@dataclass(frozen=True)
class BindContext:
    """Where a call happens: the robot, the group, and the cell model (None when there is none).

    ``suggest`` False leaves 'did you mean' out of unknown-name messages: a validator that has
    already suggested for many names stops paying for more (core_functions.suggest).
    """

    robot: RobotModel
    group: str
    cell: CellView | None = None
    suggest: bool = True


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a function, as documented in the catalog."""

    name: str
    type: ParamType
    doc: str
    unit: str = ""
    default: str | None = None  # None: required; otherwise the text used when the param is left out
    choices: tuple[str, ...] = ()
    minimum: float | None = None
    maximum: float | None = None
    kinds: tuple[str, ...] = ()  # for FRAME/ELEMENT/TARGET: the cell kinds accepted (empty: any)

    @property
    def required(self) -> bool:
        return self.default is None

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "type": self.type.value, "doc": self.doc, "required": self.required}
        if self.unit:
            out["unit"] = self.unit
            families = [u.strip() for u in self.unit.split(",")]
            out["unit_suffixes"] = sorted({s for u in families for s in _UNITS.get(u, {}) if s})
        if self.default is not None:
            out["default"] = self.default
        if self.choices:
            out["choices"] = list(self.choices)
        if self.minimum is not None:
            out["minimum"] = self.minimum
        if self.maximum is not None:
            out["maximum"] = self.maximum
        if self.kinds:
            out["kinds"] = list(self.kinds)
        return out

    # -------------------------------------------------------------------------- parsing
    def parse(self, text: str, ctx: BindContext) -> Any:
        """The typed value of ``text``; raises ValueError with a message for the user."""
        if len(text) > MAX_PARAM_LENGTH:
            raise ValueError(f"value is {len(text)} characters long (limit {MAX_PARAM_LENGTH})")
        parser = _PARSERS[self.type]
        return parser(self, text.strip(), ctx)

    def _number(self, text: str, field: str | None = None, physical: bool = True) -> float:
        """The number in SI units; outside its unit family's physical bound (core_functions.limits,
        unless ``physical`` is False) or this param's own range it is refused.  ``field`` names the
        value in messages (``x``, ``roll``) when a param holds several."""
        match = _NUMBER_WITH_UNIT.match(text)
        if not match:
            raise ValueError(f"{text!r} is not a number" + (f" (unit {self.unit})" if self.unit else ""))
        number, suffix = float(match.group(1)), match.group(2)
        family = _UNITS.get(self.unit, {"": 1.0})
        if suffix not in family:
            if suffix == "" and self.unit:
                factor = 1.0
            else:
                allowed = ", ".join(repr(s) for s in sorted(family) if s) or "none"
                raise ValueError(f"unit {suffix!r} does not fit this parameter (unit {self.unit or 'none'}; suffixes: {allowed})")
        else:
            factor = family[suffix]
        value = number * factor
        if not math.isfinite(number) or not math.isfinite(value):
            raise ValueError(f"{text!r} is not a finite number")
        self._check_range(value)  # the param's own range first: tighter, and its words are the catalog's
        bound = limits.BY_UNIT.get(self.unit) if physical else None
        if bound is not None:
            shown_unit = (suffix or self.unit) if self.unit != "fraction" else suffix
            problem = bound.violation(field or self.name, number, factor, shown_unit)
            if problem is not None:
                raise ValueError(problem)
        return value

    def _check_range(self, value: float) -> None:
        if self.minimum is not None and value < self.minimum:
            raise ValueError(f"{value:g} {self.unit} is below the minimum {self.minimum:g}".replace("  ", " "))
        if self.maximum is not None and value > self.maximum:
            raise ValueError(f"{value:g} {self.unit} is above the maximum {self.maximum:g}".replace("  ", " "))


def _parse_number(spec: ParamSpec, text: str, ctx: BindContext) -> float:
    return spec._number(text)


def _parse_integer(spec: ParamSpec, text: str, ctx: BindContext) -> int:
    if not re.fullmatch(r"[-+]?\d{1,18}", text):
        raise ValueError(f"{text!r} is not an integer")
    value = int(text)
    spec._check_range(value)
    return value


def _parse_boolean(spec: ParamSpec, text: str, ctx: BindContext) -> bool:
    lowered = text.lower()
    if lowered in ("true", "yes", "1", "on"):
        return True
    if lowered in ("false", "no", "0", "off"):
        return False
    raise ValueError(f"{text!r} is not true or false")


def _parse_text(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    if not text:
        raise ValueError("is empty")
    return text


def _parse_choice(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    if text not in spec.choices:
        raise ValueError(f"{text!r} is not one of {', '.join(spec.choices)}")
    return text


def _parse_name(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    if not _IDENTIFIER.match(text) or len(text) > 128:
        raise ValueError(f"{text!r} is not a valid name (letters, digits, '_', '.', '-'; not starting with a digit)")
    return text


def _check_kind(spec: ParamSpec, what: str, name: str, kind: str) -> None:
    if spec.kinds and kind not in spec.kinds:
        raise ValueError(f"{what} {name!r} is a {kind}, expected {' or '.join(spec.kinds)}")


def _parse_frame(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    _parse_name(spec, text, ctx)
    if ctx.cell is None:
        raise ValueError(f"frame {text!r} needs a cell model, and the application names none")
    if not ctx.cell.has_frame(text):
        hint = did_you_mean(ctx.cell.suggest_frame(text)) if ctx.suggest else ""
        raise ValueError(f"unknown frame {text!r} in the cell model{hint}")
    _check_kind(spec, "frame", text, ctx.cell.frame_kind(text))
    return text


def _parse_element(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    _parse_name(spec, text, ctx)
    if ctx.cell is None:
        raise ValueError(f"element {text!r} needs a cell model, and the application names none")
    if not ctx.cell.has_element(text):
        raise ValueError(f"unknown element {text!r} in the cell model")
    _check_kind(spec, "element", text, ctx.cell.element_kind(text))
    return text


def _parse_frames(spec: ParamSpec, text: str, ctx: BindContext) -> tuple[str, ...]:
    names = [t for t in re.split(r"[,\s]+", text) if t]
    if not names:
        raise ValueError("no frame names given")
    return tuple(_parse_frame(spec, name, ctx) for name in names)


def _numbers(text: str, unit_spec: ParamSpec, fields: Sequence[str] = (), physical: bool = True) -> list[float]:
    """Comma- or space-separated numbers; a unit may follow each number or the whole list.

    ``fields`` names the values in messages (``x``, ``y``, ``z``); ``physical`` False leaves the
    family bound to a tighter check that follows (joint limits)."""
    tokens = [t for t in re.split(r"[,\s]+", text) if t]
    trailing = ""
    if tokens and re.fullmatch(r"[A-Za-z/%]+", tokens[-1]):
        trailing = tokens.pop()
    if not tokens:
        raise ValueError("no numbers given")
    return [
        unit_spec._number(t + trailing if trailing and re.fullmatch(r"[-+.\deE]+", t) else t,
                          fields[i] if i < len(fields) else None, physical)
        for i, t in enumerate(tokens)
    ]


_XYZ = ParamSpec("xyz", ParamType.NUMBER, "", unit="m")
_RPY = ParamSpec("rpy", ParamType.NUMBER, "", unit="rad")


def _parse_target(spec: ParamSpec, text: str, ctx: BindContext) -> str | Pose:
    if _IDENTIFIER.match(text):
        return _parse_frame(spec, text, ctx)
    tokens = [t for t in re.split(r"[,\s]+", text) if t]
    if len(tokens) != 6:
        raise ValueError(f"{text!r} is neither a frame name nor 6 numbers x,y,z,roll,pitch,yaw")
    xyz = _numbers(",".join(tokens[:3]), _XYZ, ("x", "y", "z"))
    rpy = _numbers(",".join(tokens[3:]), _RPY, ("roll", "pitch", "yaw"))
    return Pose.from_xyz_rpy(*xyz, *rpy)


def _parse_joints(spec: ParamSpec, text: str, ctx: BindContext) -> tuple[float, ...]:
    # Joint limits are the bound here, tighter than any angle bound, and their message says more.
    values = _numbers(text, ParamSpec(spec.name, ParamType.NUMBER, "", unit="rad"), physical=False)
    group = ctx.robot.group(ctx.group)
    if len(values) != len(group.joints):
        raise ValueError(f"{len(values)} joint values for {ctx.group}, which has {len(group.joints)} joints ({', '.join(group.joint_names)})")
    for joint, value in zip(group.joints, values):
        if not joint.contains(value):
            hint = " (these look like degrees: write 'deg' after the list)" if abs(value) > 2 * math.pi and "deg" not in text else ""
            raise ValueError(
                f"{joint.name} = {math.degrees(value):.2f} deg is outside its limits "
                f"[{math.degrees(joint.lower):.1f}, {math.degrees(joint.upper):.1f}] deg{hint}"
            )
    return tuple(values)


def _parse_joint_pose(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    _parse_name(spec, text, ctx)
    if text in ctx.robot.poses:
        return text
    if ctx.cell is not None and ctx.cell.has_joint_pose(text):
        only = ctx.cell.joint_pose_group(text)
        if only is not None and "robot" in spec.kinds:
            raise ValueError(f"joint pose {text!r} is for {only} only; this function needs a whole-robot pose (a <joint_pose> without group)")
        return text
    known = sorted(ctx.robot.poses)
    raise ValueError(f"unknown joint pose {text!r} (robot poses: {', '.join(known)}; or a <joint_pose> of the cell)")


def _parse_group(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    if text not in ctx.robot.group_names:
        raise ValueError(f"{text!r} is not a group of {ctx.robot.name} ({', '.join(ctx.robot.group_names)})")
    if text == ctx.group:
        raise ValueError(f"{text!r} is the calling group itself")
    return text


def _parse_camera(spec: ParamSpec, text: str, ctx: BindContext) -> str:
    if text == "auto" or text in ctx.robot.cameras:
        return text
    raise ValueError(f"{text!r} is not a camera of {ctx.robot.name} (cameras: {', '.join(ctx.robot.cameras)}, or auto)")


_PARSERS: dict[ParamType, Callable[[ParamSpec, str, BindContext], Any]] = {
    ParamType.NUMBER: _parse_number,
    ParamType.INTEGER: _parse_integer,
    ParamType.BOOLEAN: _parse_boolean,
    ParamType.TEXT: _parse_text,
    ParamType.CHOICE: _parse_choice,
    ParamType.NAME: _parse_name,
    ParamType.FRAME: _parse_frame,
    ParamType.FRAMES: _parse_frames,
    ParamType.ELEMENT: _parse_element,
    ParamType.TARGET: _parse_target,
    ParamType.JOINTS: _parse_joints,
    ParamType.JOINT_POSE: _parse_joint_pose,
    ParamType.GROUP: _parse_group,
    ParamType.CAMERA: _parse_camera,
}


# --------------------------------------------------------------------------- outcomes
@dataclass(frozen=True)
class Outcome:
    """A named way a function can end that an application may branch on (``<if outcome=...>``).

    ``fault``: the fault kind (``node_transport.wire.FaultKind`` value) that ends the function with
    this outcome instead of an error -- but only where an ``<if>`` tests it: an application that does
    not say what to do when a hole is not found keeps today's error and policy.  None: the outcome
    of a function that ends normally (a function has at most one such)."""

    name: str
    doc: str
    fault: str | None = None


#: The outcomes of a function that finds something with a camera.
FOUND = Outcome("found", "the camera found the feature within its search radius; later moves use the measured pose")
NOT_FOUND = Outcome("not_found", "the camera did not find it (a vision fault: a hole not drilled, covered, or out of place)", "vision")
VISION_OUTCOMES = (FOUND, NOT_FOUND)
#: The outcomes of a function that measures a value and checks it against a range.
IN_RANGE = Outcome("in_range", "the measured value lies within the range given")
OUT_OF_RANGE = Outcome("out_of_range", "the measured value lies outside the range given (the run report says what was measured)", "out_of_range")
MEASURE_OUTCOMES = (IN_RANGE, OUT_OF_RANGE, NOT_FOUND)


# --------------------------------------------------------------------------- functions
@dataclass(frozen=True)
class FunctionSpec:
    """One function of the catalog."""

    name: str
    doc: str
    params: tuple[ParamSpec, ...]
    library: str
    group_kinds: tuple[str, ...] = ("arm",)  # which kinds of group may call it
    states: tuple[str, ...] = ()  # machine states its primitives use (for the docs)
    sync: str | None = None  # "full_body" / "master_slave": needs partner groups in the same operation
    requires: Hold | None = None  # what the hand must hold before (plausibility check)
    leaves: Hold | None = None  # what the hand holds after (None: unchanged)
    method: str = ""  # the Python method implementing it
    outcomes: tuple[Outcome, ...] = ()  # the named endings an <if> may test (none: it only succeeds or fails)

    def outcome(self, name: str) -> Outcome | None:
        return next((o for o in self.outcomes if o.name == name), None)

    def outcome_of(self, succeeded: bool, fault: str | None) -> str | None:
        """The named outcome of an ending: success -> the outcome without a fault; a failure whose
        fault kind an outcome names -> that outcome; anything else (or no outcomes) -> None."""
        for outcome in self.outcomes:
            if (outcome.fault is None) if succeeded else (fault is not None and outcome.fault == fault):
                return outcome.name
        return None

    @property
    def required_count(self) -> int:
        return sum(1 for p in self.params if p.required)

    def signature(self) -> str:
        parts = [p.name if p.required else f"{p.name}={p.default}" for p in self.params]
        return f"{self.name}({', '.join(parts)})"

    def bind(self, raw: Sequence[str], ctx: BindContext) -> list[Any]:
        """Parse the raw param texts into typed arguments; raises ParamError on the first problem
        (the first :meth:`check` lists), each text parsed once: a machine binds every request."""
        if ctx.robot.group(ctx.group).kind not in self.group_kinds or not (self.required_count <= len(raw) <= len(self.params)):
            raise self.check(raw, ctx)[0]
        args = []
        for index, (spec, text) in enumerate(zip(self.params, self._with_defaults(raw))):
            problem = None
            try:
                args.append(spec.parse(text, ctx))
            except ValueError as error:
                if index >= len(raw):  # a default text: not the caller's problem, raised as it is
                    raise
                problem = ParamError(index, f"param {index + 1} ({spec.name}) of {self.name}: {error}")
            if problem is not None:  # the params before it parsed: check's first problem
                raise problem
        return args

    def check(self, raw: Sequence[str], ctx: BindContext) -> list[ParamError]:
        """Every problem with a call: count, group kind, each param's type and references."""
        problems: list[ParamError] = []
        group = ctx.robot.group(ctx.group)
        if group.kind not in self.group_kinds:
            problems.append(ParamError(None, f"{self.name} cannot run on {ctx.group} (a {group.kind} group); it runs on: {', '.join(self.group_kinds)}"))
        if not (self.required_count <= len(raw) <= len(self.params)):
            expected = str(len(self.params)) if self.required_count == len(self.params) else f"{self.required_count} to {len(self.params)}"
            problems.append(ParamError(None, f"{self.signature()} takes {expected} params, got {len(raw)}"))
            return problems
        for index, (spec, text) in enumerate(zip(self.params, raw)):
            try:
                spec.parse(text, ctx)
            except ValueError as error:
                problems.append(ParamError(index, f"param {index + 1} ({spec.name}) of {self.name}: {error}"))
        return problems

    def _with_defaults(self, raw: Sequence[str]) -> list[str]:
        return [*raw, *[p.default or "" for p in self.params[len(raw):]]]

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name,
            "library": self.library,
            "signature": self.signature(),
            "doc": self.doc,
            "groups": list(self.group_kinds),
            "params": [p.describe() for p in self.params],
        }
        if self.states:
            out["states"] = list(self.states)
        if self.sync:
            out["sync"] = self.sync
        if self.requires is not None:
            out["requires_holding"] = self.requires.value
        if self.leaves is not None:
            out["leaves_holding"] = self.leaves.value
        if self.outcomes:
            out["outcomes"] = [
                {"name": o.name, "doc": o.doc, **({"on_fault": o.fault} if o.fault else {})} for o in self.outcomes
            ]
        return out


_SKILL_ATTR = "__skill_spec__"


@dataclass(frozen=True)
class _SkillMark:
    params: tuple[ParamSpec, ...]
    group_kinds: tuple[str, ...]
    states: tuple[str, ...]
    sync: str | None
    requires: Hold | None
    leaves: Hold | None
    name: str | None
    outcomes: tuple[Outcome, ...] = ()


def skill(
    *params: ParamSpec,
    groups: Sequence[str] = ("arm",),
    states: Sequence[str] = (),
    sync: str | None = None,
    requires: Hold | None = None,
    leaves: Hold | None = None,
    name: str | None = None,
    outcomes: Sequence[Outcome] = (),
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a method as a catalog function; its docstring becomes the catalog doc."""

    def mark(method: Callable[..., Any]) -> Callable[..., Any]:
        signature = inspect.signature(method)
        arg_names = [p for p in signature.parameters if p != "self"]
        if arg_names != [p.name for p in params]:
            raise TypeError(f"{method.__qualname__}: params {[p.name for p in params]} do not match arguments {arg_names}")
        if sum(1 for o in outcomes if o.fault is None) > 1 or len({o.name for o in outcomes}) != len(outcomes):
            raise TypeError(f"{method.__qualname__}: outcomes need distinct names and at most one without a fault")
        setattr(method, _SKILL_ATTR, _SkillMark(tuple(params), tuple(groups), tuple(states), sync, requires, leaves, name, tuple(outcomes)))
        return method

    return mark


@dataclass
class Catalog:
    """All functions of a set of function classes, by name."""

    functions: dict[str, FunctionSpec] = field(default_factory=dict)

    @staticmethod
    def from_classes(classes: Mapping[str, type]) -> Catalog:
        """Collect the marked methods of ``{library: class}``; a name defined twice is an error."""
        catalog = Catalog()
        for library, cls in classes.items():
            for attr in dir(cls):
                method = getattr(cls, attr)
                mark: _SkillMark | None = getattr(method, _SKILL_ATTR, None)
                if mark is None:
                    continue
                fname = mark.name or attr
                owner = _defining_library(cls, attr, classes)
                if owner != library:
                    continue  # inherited: listed under the library that defines it
                if fname in catalog.functions:
                    raise ValueError(f"function {fname!r} is defined by both {catalog.functions[fname].library} and {library}")
                doc = inspect.cleandoc(method.__doc__ or "").strip()
                if not doc:
                    raise ValueError(f"function {fname!r} of {library} has no docstring: the catalog needs one")
                catalog.functions[fname] = FunctionSpec(
                    name=fname,
                    doc=doc,
                    params=mark.params,
                    library=library,
                    group_kinds=mark.group_kinds,
                    states=mark.states,
                    sync=mark.sync,
                    requires=mark.requires,
                    leaves=mark.leaves,
                    method=attr,
                    outcomes=mark.outcomes,
                )
        return catalog

    def __contains__(self, name: object) -> bool:
        return name in self.functions

    def get(self, name: str) -> FunctionSpec | None:
        return self.functions.get(name)

    def names(self) -> list[str]:
        return sorted(self.functions)

    def suggest(self, name: str) -> str:
        """' (did you mean ...?)' for an unknown function name, or ''."""
        return did_you_mean(NameIndex(self.functions).suggest(name))

    def describe(self) -> list[dict[str, Any]]:
        return [self.functions[n].describe() for n in self.names()]


def _defining_library(cls: type, attr: str, classes: Mapping[str, type]) -> str | None:
    """The library whose class body defines ``attr`` (core functions are listed once, as core)."""
    for klass in cls.__mro__:
        if attr in vars(klass):
            for library, candidate in classes.items():
                if candidate is klass:
                    return library
            return None
    return None
