"""The primitives: the robot API every skill is made of, and the unit a bridge executes.

A skill (a function of the application XML) expands into a sequence of primitives; the group
machine runs each primitive as one Ready -> <state> -> Ready cycle, where ``<state>`` is the
primitive's :attr:`STATE` (paper Table 1), and a bridge carries it to a robot.  Primitives are
robot-independent and in SI units (m, rad, s; REP 103); poses are in the robot's world frame
(for Nextage: ``WAIST``), already resolved from cell-model names by the skill.

Each primitive names the result type its bridge returns (:attr:`RESULT`), so skills can use what
a primitive measured -- a vision correction feeding the next move, for instance.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, ClassVar, Literal, Union

from core_functions.geometry import Pose


class WorkState(Enum):
    """The working states of the group machine (paper Table 1) and the request signal into each."""

    MOTION = "Motion"
    FULL_BODY_MOTION = "FullBodyMotion"
    RECORD_TRAJECTORY = "RecordTrajectory"
    TRAJECTORY_EXECUTION = "TrajectoryExecution"
    END_EFFECTOR = "EndEffector"
    VISION = "Vision"
    MASTER_SLAVE = "MasterSlave"

    @property
    def request_signal(self) -> str:
        return _REQUEST_SIGNALS[self]


_REQUEST_SIGNALS = {
    WorkState.MOTION: "motion_request",
    WorkState.FULL_BODY_MOTION: "full_body_request",
    WorkState.RECORD_TRAJECTORY: "record_trajectory_request",
    WorkState.TRAJECTORY_EXECUTION: "trajectory_execution_request",
    WorkState.END_EFFECTOR: "end_effector_request",
    WorkState.VISION: "vision_request",
    WorkState.MASTER_SLAVE: "master_slave_request",
}

Interpolation = Literal["ptp", "linear"]
EndEffectorAction = Literal[
    "gripper_open",
    "gripper_close",
    "air_on",
    "air_off",
    "tool_on",
    "tool_off",
    "hand_draw_in",
    "hand_keep",
    "hand_release",
]
END_EFFECTOR_ACTIONS: tuple[str, ...] = EndEffectorAction.__args__  # type: ignore[attr-defined]


# --------------------------------------------------------------------------------- results
@dataclass(frozen=True)
class MotionResult:
    """Where the group ended: joint positions (rad) and TCP pose in the world frame."""

    KIND: ClassVar[str] = "motion"

    joint_names: tuple[str, ...] = ()
    positions: tuple[float, ...] = ()
    tcp: Pose | None = None


@dataclass(frozen=True)
class EndEffectorResult:
    """The I/O state of the group's hand after the action."""

    KIND: ClassVar[str] = "end_effector"

    io: dict[str, bool] = field(default_factory=dict)


@dataclass(frozen=True)
class VisionReport:
    """How a vision result was measured, for the trace: camera, image, nominal vs measured, fit quality.

    ``method`` is ``plane`` (one image, the ray of the hole's centre met with the part plane),
    ``stereo`` (triangulated from a camera pair), ``sharpness`` (a focus measure of the image) or
    ``simulated`` (a feature the cameras have no image model of: the simulator's ground truth plus
    noise).  ``correction`` is measured minus nominal position (m, world frame); ``residual`` (m)
    is the RMS distance of the edge points from the fitted circle, or the stereo disagreement.
    """

    camera: str
    method: str
    image_size: tuple[int, int] = (0, 0)
    nominal: Pose | None = None
    measured: Pose | None = None
    correction: tuple[float, float, float] = (0.0, 0.0, 0.0)
    residual: float = 0.0
    diameter: float = 0.0
    sharpness: float = 0.0


@dataclass(frozen=True)
class VisionResult:
    """What a camera found: a measured pose (world frame), a scalar measurement, a confidence."""

    KIND: ClassVar[str] = "vision"

    pose: Pose | None = None
    value: float | None = None
    score: float = 1.0
    report: VisionReport | None = None


@dataclass(frozen=True)
class TrajectoryResult:
    """A joint trajectory: ``points[i]`` is reached at ``times[i]`` seconds after the start."""

    KIND: ClassVar[str] = "trajectory"

    joint_names: tuple[str, ...] = ()
    points: tuple[tuple[float, ...], ...] = ()
    times: tuple[float, ...] = ()


@dataclass(frozen=True)
class IoResult:
    """The signals an I/O primitive named, by name, as the controller had them when it ended (BOOL as 0/1)."""

    KIND: ClassVar[str] = "io"

    values: dict[str, float] = field(default_factory=dict)


PrimitiveResult = Union[MotionResult, EndEffectorResult, VisionResult, TrajectoryResult, IoResult]


def _finite(name: str, *values: float) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name} must be finite numbers, got {values}")


# ------------------------------------------------------------------------------ primitives
@dataclass(frozen=True)
class MoveJoints:
    """Articular move of the group's joints (absolute, or relative to the current position)."""

    KIND: ClassVar[str] = "move_joints"
    STATE: ClassVar[WorkState] = WorkState.MOTION
    RESULT: ClassVar[type] = MotionResult
    positions: tuple[float, ...]
    joint_names: tuple[str, ...] = ()
    relative: bool = False

    def __post_init__(self) -> None:
        _finite("joint positions", *self.positions)
        if self.joint_names and len(self.joint_names) != len(self.positions):
            raise ValueError(f"{len(self.positions)} positions for {len(self.joint_names)} joint names")


@dataclass(frozen=True)
class MoveCartesian:
    """Move the TCP to a world-frame pose, point-to-point (joint interpolated) or linear."""

    KIND: ClassVar[str] = "move_cartesian"
    STATE: ClassVar[WorkState] = WorkState.MOTION
    RESULT: ClassVar[type] = MotionResult
    target: Pose
    interpolation: Interpolation = "ptp"
    frame: str = ""  # the cell-model name the target came from, for traces and errors


@dataclass(frozen=True)
class MoveRelative:
    """Move the TCP by ``delta``, expressed in the world frame or in the current tool frame."""

    KIND: ClassVar[str] = "move_relative"
    STATE: ClassVar[WorkState] = WorkState.MOTION
    RESULT: ClassVar[type] = MotionResult
    delta: Pose
    reference: Literal["world", "tool"] = "world"
    interpolation: Interpolation = "linear"

    def goal(self, start: Pose) -> Pose:
        """Where the TCP ends when the move starts at ``start``: the one definition every back end and
        the machine's re-basing of a retried move use.  Tool axes: ``start * delta``.  World axes: the
        translation added, the orientation turned about the world axes through the TCP."""
        if self.reference == "tool":
            return start.compose(self.delta)
        turn = Pose(0.0, 0.0, 0.0, *self.delta.quaternion).compose(Pose(0.0, 0.0, 0.0, *start.quaternion))
        return Pose(start.x + self.delta.x, start.y + self.delta.y, start.z + self.delta.z, *turn.quaternion)


@dataclass(frozen=True)
class SetSpeed:
    """Speed of the following motions as a fraction (0, 1] of the robot's maximum."""

    KIND: ClassVar[str] = "set_speed"
    STATE: ClassVar[WorkState] = WorkState.MOTION
    RESULT: ClassVar[type] = MotionResult
    fraction: float

    def __post_init__(self) -> None:
        if not (0.0 < self.fraction <= 1.0):
            raise ValueError(f"speed fraction must be in (0, 1], got {self.fraction}")


@dataclass(frozen=True)
class Dwell:
    """Hold the current position for ``seconds`` (a motion of zero length: pausable, stoppable)."""

    KIND: ClassVar[str] = "dwell"
    STATE: ClassVar[WorkState] = WorkState.MOTION
    RESULT: ClassVar[type] = MotionResult
    seconds: float

    def __post_init__(self) -> None:
        if not (self.seconds >= 0.0 and math.isfinite(self.seconds)):
            raise ValueError(f"dwell needs a finite duration >= 0 s, got {self.seconds}")


@dataclass(frozen=True)
class EndEffector:
    """A tool or hand action: gripper, air, deburring spindle, Nextage air hand."""

    KIND: ClassVar[str] = "end_effector"
    STATE: ClassVar[WorkState] = WorkState.END_EFFECTOR
    RESULT: ClassVar[type] = EndEffectorResult
    action: EndEffectorAction


@dataclass(frozen=True)
class SetOutput:
    """Set a signal the controller receives, by the name its configuration gives it (KUKA RSI: ``GPIO.01``,
    ``Tech.T21``); done once the value has left for the controller.  BOOL signals take 0 or 1."""

    KIND: ClassVar[str] = "set_output"
    STATE: ClassVar[WorkState] = WorkState.END_EFFECTOR
    RESULT: ClassVar[type] = IoResult
    name: str
    value: float

    def __post_init__(self) -> None:
        _finite(f"output {self.name}", self.value)


@dataclass(frozen=True)
class WaitInput:
    """Hold still until a signal the controller sends reads ``value`` (within ``tolerance``), failing
    with a timeout after ``timeout`` seconds of robot time."""

    KIND: ClassVar[str] = "wait_input"
    STATE: ClassVar[WorkState] = WorkState.END_EFFECTOR
    RESULT: ClassVar[type] = IoResult
    name: str
    value: float
    timeout: float = 10.0
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        _finite(f"input {self.name}", self.value, self.timeout, self.tolerance)
        if self.timeout < 0 or self.tolerance < 0:
            raise ValueError(f"input {self.name}: timeout and tolerance must be >= 0, got {self.timeout}, {self.tolerance}")


@dataclass(frozen=True)
class Vision:
    """A vision operation: locate a feature (returns its measured pose), inspect or measure."""

    KIND: ClassVar[str] = "vision"
    STATE: ClassVar[WorkState] = WorkState.VISION
    RESULT: ClassVar[type] = VisionResult
    task: Literal["locate", "inspect", "measure"]
    target: str = ""
    nominal: Pose | None = None
    camera: str = ""


@dataclass(frozen=True)
class RecordTrajectory:
    """Record a trajectory: planned through waypoints, or taught by sampling the joints.

    A ``linear`` plan is replayed by joint interpolation between its samples, so the bridge
    samples each straight line where it must for the replay to stay within ``tolerance`` (m) of
    the line's position and ``angle_tolerance`` (rad) of its orientation, and fails the
    recording where it cannot; ``sample_period`` is then the longest gap between samples.
    """

    KIND: ClassVar[str] = "record_trajectory"
    STATE: ClassVar[WorkState] = WorkState.RECORD_TRAJECTORY
    RESULT: ClassVar[type] = TrajectoryResult
    name: str
    mode: Literal["plan", "teach"] = "plan"
    waypoints: tuple[Pose, ...] = ()
    interpolation: Interpolation = "ptp"
    duration: float = 0.0
    sample_period: float = 0.1
    tolerance: float = 1e-4  # m: 0.1 mm
    angle_tolerance: float = math.radians(0.1)  # rad: 0.1 deg

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("a recorded trajectory needs a name")
        if not (self.tolerance > 0 and self.angle_tolerance > 0 and math.isfinite(self.tolerance + self.angle_tolerance)):
            raise ValueError(f"path tolerances must be positive finite numbers, got {self.tolerance} m, {self.angle_tolerance} rad")
        if self.mode == "plan" and not self.waypoints:
            raise ValueError("planning a trajectory needs at least one waypoint")
        if self.mode == "teach" and not (self.duration > 0 and self.sample_period > 0):
            raise ValueError("teaching needs a duration and a sample period > 0")


@dataclass(frozen=True)
class ExecuteTrajectory:
    """Replay a joint trajectory (points reached at the given times, scaled by the set speed)."""

    KIND: ClassVar[str] = "execute_trajectory"
    STATE: ClassVar[WorkState] = WorkState.TRAJECTORY_EXECUTION
    RESULT: ClassVar[type] = MotionResult
    name: str
    joint_names: tuple[str, ...]
    points: tuple[tuple[float, ...], ...]
    times: tuple[float, ...]

    def __post_init__(self) -> None:
        if not self.points or len(self.points) != len(self.times):
            raise ValueError(f"trajectory {self.name!r}: {len(self.points)} points for {len(self.times)} times")
        if any(len(p) != len(self.joint_names) for p in self.points):
            raise ValueError(f"trajectory {self.name!r}: every point needs {len(self.joint_names)} values")
        if any(b < a for a, b in zip(self.times, self.times[1:])):
            raise ValueError(f"trajectory {self.name!r}: times must not decrease")


@dataclass(frozen=True)
class FullBodyMove:
    """One coordinated move of every joint of the robot (15 on Nextage); sent once both arms agree."""

    KIND: ClassVar[str] = "full_body_move"
    STATE: ClassVar[WorkState] = WorkState.FULL_BODY_MOTION
    RESULT: ClassVar[type] = MotionResult
    joint_names: tuple[str, ...]
    positions: tuple[float, ...]

    def __post_init__(self) -> None:
        _finite("joint positions", *self.positions)
        if len(self.joint_names) != len(self.positions):
            raise ValueError(f"{len(self.positions)} positions for {len(self.joint_names)} joints")


@dataclass(frozen=True)
class MasterSlaveMove:
    """Bi-manual move: the master's TCP path, and the slave's derived with a fixed offset.

    ``slave_path[i] = master_path[i] * offset``, where the offset is the slave TCP expressed in
    the master TCP frame; ``offset=None`` means "the offset the two TCPs have when the move
    starts" (a part held by both hands stays held).  The slave's machine holds a copy with an
    empty ``master_path``: only the master's copy, which has the path, is sent to a bridge.
    """

    KIND: ClassVar[str] = "master_slave_move"
    STATE: ClassVar[WorkState] = WorkState.MASTER_SLAVE
    RESULT: ClassVar[type] = MotionResult
    master: str
    slave: str
    master_path: tuple[Pose, ...] = ()
    offset: Pose | None = None

    def __post_init__(self) -> None:
        if self.master == self.slave:
            raise ValueError("master and slave must be different groups")

    def slave_path(self, offset: Pose) -> tuple[Pose, ...]:
        """The slave's waypoints for ``offset`` (pass ``self.offset`` or the measured start offset)."""
        return tuple(p.compose(offset) for p in self.master_path)


Primitive = Union[
    MoveJoints,
    MoveCartesian,
    MoveRelative,
    SetSpeed,
    Dwell,
    EndEffector,
    Vision,
    RecordTrajectory,
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    SetOutput,
    WaitInput,
]


def describe(primitive: Any) -> str:
    """One line for logs and traces: the kind and its main argument."""
    kind = primitive.KIND
    if isinstance(primitive, MoveCartesian):
        return f"{kind}({primitive.frame or primitive.target}, {primitive.interpolation})"
    if isinstance(primitive, EndEffector):
        return f"{kind}({primitive.action})"
    if isinstance(primitive, Vision):
        return f"{kind}({primitive.task} {primitive.target})"
    if isinstance(primitive, (RecordTrajectory, ExecuteTrajectory)):
        return f"{kind}({primitive.name})"
    if isinstance(primitive, SetSpeed):
        return f"{kind}({primitive.fraction:g})"
    if isinstance(primitive, Dwell):
        return f"{kind}({primitive.seconds:g} s)"
    if isinstance(primitive, (SetOutput, WaitInput)):
        return f"{kind}({primitive.name} = {primitive.value:g})"
    return kind
