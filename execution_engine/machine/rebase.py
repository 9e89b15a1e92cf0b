"""Relative moves are never repeated blindly: a retry re-bases them on the goal the first attempt fixed.

The engine retries a failed function by sending it again (``SmRequest.attempt`` one higher); the
skill starts over and yields its primitives again.  An absolute target sent again is harmless --
the robot goes where it already is, or finishes the way there -- but a relative one is not: a
20 mm ``move_relative`` whose link dropped after the controller had run it would run again and
move the arm 40 mm.  So before a relative primitive (``MoveRelative``, ``MoveJoints(relative=True)``)
may be sent, the machine measures where the arm is (the bridge's ``measure``) and fixes the
absolute goal the move resolves to from there, by the same definition the back ends use
(:meth:`core_functions.primitives.MoveRelative.goal`).  The relative primitive then goes out as
it is (V+ still runs its ``move_rel_tool``).  Goals are kept per call -- operation, function and
parameters -- and primitive index, and only for the attempts of that call:

* a retry that yields, at the same index after the same primitives, the same relative primitive
  sends the goal recorded instead, as an absolute move (``MoveCartesian`` with the primitive's
  interpolation, or an absolute ``MoveJoints``): it ends where the first attempt's move would have
  ended, whatever part of it the robot did;
* once a retry yields something else (a measurement came out differently, and the skill took
  another branch), the earlier attempts' plan no longer applies from that index on: what follows
  is measured and fixed afresh;
* a relative primitive that may have run but whose goal could not be fixed (the bridge reported
  no TCP, or not the joints) is refused on a retry rather than sent again;
* a first attempt (``attempt`` 1) or another call starts with nothing recorded, so a goal never
  outlives the retries of its call.
"""
from __future__ import annotations

from dataclasses import dataclass

from core_functions.primitives import MotionResult, MoveCartesian, MoveJoints, MoveRelative, Primitive, describe
from node_transport.wire import SmRequest

CallKey = tuple[str, str, tuple[str, ...]]


def is_relative(primitive: object) -> bool:
    """Whether sending ``primitive`` twice would move the robot twice."""
    return isinstance(primitive, MoveRelative) or (isinstance(primitive, MoveJoints) and primitive.relative)


def absolute(primitive: Primitive, measured: MotionResult, group_joints: tuple[str, ...], label: str) -> Primitive | None:
    """The absolute move ``primitive`` (relative) resolves to from ``measured``; None without the pose it needs."""
    if isinstance(primitive, MoveRelative):
        if measured.tcp is None:
            return None
        return MoveCartesian(primitive.goal(measured.tcp), primitive.interpolation, frame=label)
    assert isinstance(primitive, MoveJoints)
    names = primitive.joint_names or group_joints
    at = dict(zip(measured.joint_names, measured.positions))
    if len(names) != len(primitive.positions) or any(name not in at for name in names):
        return None
    return MoveJoints(tuple(at[name] + delta for name, delta in zip(names, primitive.positions)), tuple(names))


@dataclass(frozen=True)
class Step:
    """One primitive of the running call: what the skill asked for and what goes to the bridge."""

    index: int  # 0-based, within the call
    asked: Primitive
    send: Primitive
    needs_goal: bool = False  # relative, sent as such: measure and fix its goal first
    refusal: str | None = None  # a retry met a relative move that may have run, with no goal to re-base it on


class RelativeGoals:
    """The goals the relative moves of one call resolved to, across the attempts of that call."""

    def __init__(self) -> None:
        self._key: CallKey | None = None
        self._asked: list[Primitive] = []  # what the skill yielded at each index, latest attempt that got there
        self._goals: dict[int, Primitive | None] = {}  # index -> absolute goal of a relative primitive (None: unknown)
        self._attempt = 1
        self._same_plan = False  # this attempt has so far yielded what the earlier ones did
        self.current: Step | None = None  # the step a working state runs

    def begin(self, request: SmRequest) -> None:
        """A call starts: a retry of the call before keeps its goals; anything else forgets them."""
        key: CallKey = (request.operation, request.function, tuple(request.params))
        if request.attempt > 1 and key == self._key:
            self._same_plan = True
        else:
            self._key, self._asked, self._goals = key, [], {}
            self._same_plan = False
        self._attempt = request.attempt
        self.current = None

    def step(self, index: int, primitive: Primitive) -> Step:
        """What to send for the skill's ``index``-th primitive (no side effect: Ready may ask again)."""
        if self._repeats(index, primitive) and index in self._goals:
            goal = self._goals[index]
            if goal is None:
                why = (
                    f"{describe(primitive)} (primitive {index + 1}) may have run in an earlier attempt, and the bridge reported "
                    "no pose to fix its goal from: not sent again; check where the arm is"
                )
                return Step(index, primitive, primitive, refusal=why)
            return Step(index, primitive, goal)
        return Step(index, primitive, primitive, needs_goal=is_relative(primitive))

    def take(self, step: Step) -> None:
        """``step`` goes to a working state; from a new branch on, the earlier attempts' plan is dropped."""
        index = step.index
        if not self._repeats(index, step.asked):
            self._same_plan = False
            del self._asked[index:]
            for later in [i for i in self._goals if i >= index]:
                del self._goals[later]
            self._asked.append(step.asked)
        self.current = step

    def record(self, index: int, goal: Primitive | None) -> None:
        """The absolute goal the relative primitive at ``index`` resolved to, fixed before it is sent."""
        self._goals[index] = goal

    def label(self, index: int, primitive: Primitive) -> str:
        """How a re-based goal shows in traces: the move it stands for, and where it was fixed."""
        return f"goal of {describe(primitive)} #{index + 1}, attempt {self._attempt}"

    def _repeats(self, index: int, primitive: Primitive) -> bool:
        return self._same_plan and index < len(self._asked) and self._asked[index] == primitive
