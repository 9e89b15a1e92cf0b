"""The cell model as skills see it: named frames resolved to the world frame, elements, joint poses.

The application's cell model XML is loaded once, by the engine, which publishes it resolved to
world poses (a ``CellSnapshot``); each group machine wraps that in a :class:`CellIndex`, so
skills look frames up by name without knowing where the model came from.  Vision corrections
are kept beside the nominal poses (:meth:`CellIndex.correct`), never overwriting them: a
re-run starts from the nominal cell again.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from core_functions.geometry import Pose
from core_functions.suggest import NameIndex


@dataclass(frozen=True)
class CellFrame:
    """A named frame of the cell, resolved to the world frame, with its attributes."""

    name: str
    pose: Pose
    kind: str = "frame"
    parent: str = "world"
    attributes: dict[str, str] = field(default_factory=dict)


class _Kinded(Protocol):
    @property
    def kind(self) -> str: ...


class FrameLookup(ABC):
    """The frame half of catalog.CellView over a map of named frames, for every cell model.

    The loaded cell (app_model) and a group machine's index of the published one hold frames of
    different types; both answer the catalog's questions about them the same way, here."""

    _names: NameIndex  # sorted on the first unknown name only

    @property
    @abstractmethod
    def frame_map(self) -> Mapping[str, _Kinded]:
        """Every frame by name (``world`` is not one of them)."""

    def has_frame(self, name: str) -> bool:
        return name == "world" or name in self.frame_map

    def frame_kind(self, name: str) -> str:
        return "world" if name == "world" else self.frame_map[name].kind

    def frame_names(self) -> Iterable[str]:
        return self.frame_map.keys()

    def suggest_frame(self, name: str) -> str | None:
        """The frame name closest to an unknown ``name``, at a bounded cost (core_functions.suggest)."""
        return self._names.suggest(name)


class CellIndex(FrameLookup):
    """Lookup of frames, elements and joint poses by name (implements catalog.CellView)."""

    def __init__(
        self,
        name: str,
        frames: Iterable[CellFrame],
        elements: Mapping[str, Mapping[str, str]] | None = None,
        joint_poses: Mapping[str, Mapping[str, float]] | None = None,
        joint_pose_groups: Mapping[str, str] | None = None,
    ) -> None:
        self.name = name
        self._frames = {f.name: f for f in frames}
        self._elements = {k: dict(v) for k, v in (elements or {}).items()}
        self._joint_poses = {k: dict(v) for k, v in (joint_poses or {}).items()}
        self._joint_pose_groups = dict(joint_pose_groups or {})
        self._measured: dict[str, Pose] = {}
        self._names = NameIndex(self._frames)  # sorted on the first unknown name only
        #: Told ``(frame, measured world pose)`` after each correction: the group machine passes
        #: corrections on to the engine, which publishes the cell's frames on tf_static.
        self.on_correct: Callable[[str, Pose], None] | None = None

    # ------------------------------------------------------------------ catalog.CellView
    @property
    def frame_map(self) -> Mapping[str, CellFrame]:
        return self._frames

    def has_element(self, name: str) -> bool:
        return name in self._elements

    def element_kind(self, name: str) -> str:
        return self._elements[name].get("kind", "element")

    def has_joint_pose(self, name: str) -> bool:
        return name in self._joint_poses

    def joint_pose_group(self, name: str) -> str | None:
        return self._joint_pose_groups.get(name)

    # --------------------------------------------------------------------------- lookup
    def frame(self, name: str) -> CellFrame:
        try:
            return self._frames[name]
        except KeyError:
            raise KeyError(f"cell {self.name!r} has no frame {name!r}") from None

    def nominal(self, name: str) -> Pose:
        """The frame's world pose as the cell model gives it."""
        return Pose() if name == "world" else self.frame(name).pose

    def pose(self, name: str) -> Pose:
        """The best known world pose of a frame.

        Its own vision measurement if it has one; otherwise, if an ancestor was located, the
        nominal pose moved with that ancestor (locating a fixture corrects every hole on it);
        otherwise the nominal pose.
        """
        measured = self._measured.get(name)
        if measured is not None:
            return measured
        nominal = self.nominal(name)
        if not self._measured:
            return nominal  # nothing located: no need to climb a chain of ancestors
        ancestor = self._frames[name].parent if name in self._frames else None
        for _ in range(len(self._frames)):  # bounded: the tree has no cycles, but never trust that
            if ancestor is None or ancestor not in self._frames:
                break
            located = self._measured.get(ancestor)
            if located is not None:
                return located.compose(self.nominal(ancestor).inverse()).compose(nominal)
            ancestor = self._frames[ancestor].parent
        return nominal

    def correct(self, name: str, measured: Pose) -> None:
        """Record where vision found ``name``; later :meth:`pose` calls for it and its children use it."""
        self.frame(name)
        self._measured[name] = measured
        if self.on_correct is not None:
            self.on_correct(name, measured)

    def corrections(self) -> dict[str, Pose]:
        """Every frame located so far, with its measured world pose (children not included)."""
        return dict(self._measured)

    def element(self, name: str) -> dict[str, str]:
        try:
            return dict(self._elements[name])
        except KeyError:
            raise KeyError(f"cell {self.name!r} has no element {name!r}") from None

    def number(self, frame_or_element: str, attribute: str, default: float | None = None) -> float:
        """A numeric attribute of a frame or element (SI units), e.g. a hole's diameter."""
        source = self._elements.get(frame_or_element)
        if source is None:
            source = self.frame(frame_or_element).attributes
        text = source.get(attribute)
        if text is None:
            if default is None:
                raise KeyError(f"{frame_or_element!r} has no attribute {attribute!r}")
            return default
        return float(text)

    def joint_pose(self, name: str) -> dict[str, float]:
        try:
            return dict(self._joint_poses[name])
        except KeyError:
            raise KeyError(f"cell {self.name!r} has no joint pose {name!r}") from None
