"""The messages between engine, group machines, bridges and viewers, and their topic names.

Every structured message is a frozen dataclass with a protocol version ``v`` (always 1) and, for
commands and their answers, a correlation ``id``.  On the wire most are the typed messages of
``dual_arm_executive_interfaces`` (:mod:`node_transport.typed` converts and
validates them); the located frames, the cell model and the barrier messages are JSON in
``std_msgs/String``, decoded with :func:`node_transport.codec.decode`.  Either way
the whole message is validated, and one that fails is reported and ignored.  Names follow the
table in docs/architecture.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Literal

from core_functions.cell_index import CellFrame, CellIndex
from core_functions.geometry import Pose
from core_functions.primitives import Primitive, PrimitiveResult

PROTOCOL_VERSION = 1


def _check_version(v: int) -> None:
    if v != PROTOCOL_VERSION:
        raise ValueError(f"protocol version {v} is not supported (this node speaks v{PROTOCOL_VERSION})")


class FaultKind(Enum):
    """Why a primitive or a function failed; it travels with the error so the engine can decide
    whether a second try can succeed (:mod:`execution_engine.engine.faults`) without reading text.

    Bridges raise every kind but SKILL; the group machine adds its own faults with the same kinds
    (a bridge that does not answer is a TIMEOUT, a stop is STOPPED, a defect is INTERNAL).
    """

    UNREACHABLE = "unreachable"  # no IK solution / outside the workspace
    JOINT_LIMIT = "joint_limit"  # a target or a path point beyond a joint limit
    COLLISION = "collision"
    VISION = "vision"  # feature not found, camera failure
    UNSUPPORTED = "unsupported"  # the robot (or the machine) cannot do this primitive or request
    STOPPED = "stopped"  # stop requested while executing
    TIMEOUT = "timeout"  # the controller, the bridge or a partner did not answer in time
    CONNECTION = "connection"  # the link to the controller (or to the bridge) broke
    PROTOCOL = "protocol"  # an answer we cannot parse, or one that does not say why it failed
    CONTROLLER = "controller"  # the controller reported a fault (RSI stop, drive error)
    BUSY = "busy"  # a primitive is already running for this group / the machine is not Ready
    INTERNAL = "internal"  # a defect in the bridge or the machine itself
    SKILL = "skill"  # the skill's own code raised (a frame it cannot find, a rivet that does not fit)
    OUT_OF_RANGE = "out_of_range"  # a value a function measured lies outside the range it checks (core_functions.functions.OutOfRange)


# --------------------------------------------------------------------- engine <-> machine
@dataclass(frozen=True)
class SmRequest:
    """Engine -> machine: run one function of one operation (or ``end``: go to Finish)."""

    id: str
    kind: Literal["execute", "end"] = "execute"
    operation: str = ""
    function: str = ""
    params: tuple[str, ...] = ()  # the <param value=...> texts; the machine parses them with the catalog
    attempt: int = 1
    sync: str = ""  # barrier key shared by the partners of a synchronised function
    partners: tuple[str, ...] = ()  # every group taking part in that synchronised function, leader first
    cell: str = ""  # the cell model (latched on execution_engine/cell) the function's names refer to
    v: int = PROTOCOL_VERSION

    def __post_init__(self) -> None:
        _check_version(self.v)
        if self.kind == "execute" and not self.function:
            raise ValueError("an execute request needs a function")


@dataclass(frozen=True)
class SmResult:
    """Machine -> engine: the outcome of a whole function."""

    id: str
    group: str
    outcome: Literal["succeeded", "aborted", "preempted"]
    operation: str = ""
    function: str = ""
    error: str | None = None
    fault: FaultKind | None = None  # with aborted / preempted: why, for the engine's retry decision
    t_start: float = 0.0
    t_end: float = 0.0
    primitives: int = 0
    v: int = PROTOCOL_VERSION

    def __post_init__(self) -> None:
        _check_version(self.v)


@dataclass(frozen=True)
class SmStatus:
    """Machine -> anyone: one event of the machine (a transition, a function or primitive edge)."""

    group: str
    event: Literal[
        "transition", "function_start", "function_end", "primitive_start", "primitive_end", "error"
    ]
    state: str
    t: float
    from_state: str | None = field(default=None, metadata={"json": "from"})
    to_state: str | None = field(default=None, metadata={"json": "to"})
    signal: str | None = None
    operation: str | None = None
    function: str | None = None
    request_id: str | None = None
    primitive: str | None = None
    index: int | None = None
    count: int | None = None
    outcome: str | None = None
    error: str | None = None
    result: dict[str, Any] | None = None  # primitive_end: what the bridge reported (TCP, joints, measurement)
    v: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class TransitionSpec:
    """One row of the transition table: ``from --signal--> to``."""

    source: str = field(metadata={"json": "from"})
    signal: str
    target: str = field(metadata={"json": "to"})


@dataclass(frozen=True)
class SmStructure:
    """Machine -> viewers (latched): the states and transitions, for drawing the machine."""

    group: str
    initial: str
    states: tuple[str, ...]
    transitions: tuple[TransitionSpec, ...]
    v: int = PROTOCOL_VERSION


# ---------------------------------------------------------------------- machine <-> bridge
@dataclass(frozen=True)
class BridgeCommand:
    """Machine -> bridge: execute a primitive, pause / resume / stop the group's motion, or measure
    where the idle group is (before a relative move, whose goal the machine fixes from it)."""

    id: str
    group: str
    op: Literal["execute", "pause", "resume", "stop", "measure"]
    primitive: Primitive | None = None
    v: int = PROTOCOL_VERSION

    def __post_init__(self) -> None:
        _check_version(self.v)
        if (self.op == "execute") != (self.primitive is not None):
            raise ValueError("an execute command carries a primitive, and only it does")


@dataclass(frozen=True)
class BridgeFeedback:
    """Bridge -> machine: what became of a command (``id`` is the command's)."""

    id: str
    group: str
    status: Literal["accepted", "done", "error", "paused", "resumed", "stopped", "measured"]
    error: str | None = None
    fault: FaultKind | None = None  # with "error": the back end's FaultKind
    result: PrimitiveResult | None = None  # with "done": what the primitive's type says it returns; "measured": a MotionResult
    t: float = 0.0
    v: int = PROTOCOL_VERSION


# --------------------------------------------------------------------------------- engine
@dataclass(frozen=True)
class GroupProgress:
    state: str
    operation: str | None = None
    function: str | None = None
    #: sync="flags": where the group stands in its own calls, as the swap event's answer says it --
    #: ``in:N`` (inside operation N, counted from 1), ``before:N`` (its next call is there), ``finished:N`` (N the count);
    #: "" in lock-step, where the engine's operation count is every group's.
    position: str = ""


@dataclass(frozen=True)
class EngineStatus:
    """Engine -> anyone: where the application is."""

    app: str
    state: Literal["idle", "running", "paused", "stepping", "error", "alarm", "stopping", "finished", "failed", "stopped"]
    operation_index: int
    operation_count: int
    t: float
    operation_id: str | None = None
    groups: dict[str, GroupProgress] = field(default_factory=dict)
    message: str = ""
    speed_override: float = 100.0  # percent, 0..100: every back end plays its motions at this share of their planned speed
    v: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class EngineEvent:
    """Engine -> anyone (``execution_engine/events``): one change of the engine's state, or one
    operator command (start, pause, resume, step, stop, reset) with who gave it and the answer.

    Not latched, unlike :class:`EngineStatus`: these are events for traces and logs, each once.
    """

    event: Literal["state", "operator", "flag", "outcome", "branch", "swap", "breakpoint"]  # flag: ``source`` the group, ``command`` the flag or zone, ``answer`` which (flag/zone), ``state`` set/waiting/passed/timeout/stopped
    # outcome: the named outcome (``answer``) a function (``command``) of ``source`` ended ``operation`` with, an <if> testing it;
    # branch: ``operation`` left out by its <if>/<else> (``source`` the tested group, ``answer`` the outcome it ended with)
    # swap: a paused run's remainder edited (``operation`` the last started, ``command`` the new application's file,
    # ``source`` who, ``answer`` "OLD_DIGEST NEW_DIGEST FRONTIER", engine/remainder_swap.py)
    # breakpoint: the run paused before ``operation`` (``command`` why: break, run_to or step; ``source`` the groups held
    # in sync="flags", none in lock-step: all; ``answer`` held, or passed: nobody could continue it); operator commands on
    # breakpoints (break, unbreak, unbreak_all, run_to) carry the operation they name in ``message`` (engine/breakpoints.py)
    # and an accepted speed_override the new percentage (engine/speed.py)
    t: float
    state: str  # the engine's state after a state change; the state a command arrived in
    operation: str | None = None
    from_state: str | None = field(default=None, metadata={"json": "from"})  # state: the state left
    message: str = ""
    command: str | None = None  # operator: the command
    source: str | None = None  # operator: the resolved service name, the terminal console, the safety stop
    accepted: bool | None = None  # operator: whether the engine took the command
    answer: str | None = None  # operator: what the engine answered
    v: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class CellSnapshot:
    """Engine -> machines and bridges (latched): the cell model the application runs in."""

    name: str
    frames: tuple[CellFrame, ...] = ()
    elements: dict[str, dict[str, str]] = field(default_factory=dict)
    joint_poses: dict[str, dict[str, float]] = field(default_factory=dict)
    truth: dict[str, Pose] = field(default_factory=dict)
    joint_pose_groups: dict[str, str] = field(default_factory=dict)  # poses made for one group only
    v: int = PROTOCOL_VERSION

    def index(self) -> CellIndex:
        return CellIndex(self.name, self.frames, self.elements, self.joint_poses, self.joint_pose_groups)


@dataclass(frozen=True)
class LocatedFrames:
    """Machine -> engine (latched ``<group>/sm/located``): where vision found frames of the cell.

    Vision corrections happen inside a machine (a skill locates a hole), but the cell's frames are
    published on ``tf_static`` by the engine alone, so that a late subscriber never receives a
    nominal pose from one sender after a corrected one from another.  ``frames`` holds every
    frame this group has located in the cell model ``cell`` since it received that model, as the
    measured world poses (the engine moves their child frames with them); being cumulative, the
    one latched message is all a late subscriber needs.  A machine sends an empty one when it
    receives a cell model: every run starts from the nominal cell.
    """

    group: str
    cell: str
    frames: dict[str, Pose] = field(default_factory=dict)
    t: float = 0.0
    v: int = PROTOCOL_VERSION

    def __post_init__(self) -> None:
        _check_version(self.v)


@dataclass(frozen=True)
class SyncMessage:
    """Machine <-> machine, for FullBodyMotion and MasterSlave: who is at the barrier, and what for."""

    group: str
    key: str
    event: Literal["arrived", "done", "failed", "left"]
    state: str
    t: float = 0.0
    error: str | None = None
    fault: FaultKind | None = None  # with "failed": why, so every partner reports the same kind
    v: int = PROTOCOL_VERSION


# ---------------------------------------------------------------------------------- names
# Every name is relative: it resolves under the node's namespace, so two cells launched with
# ``namespace:=cell_a`` and ``namespace:=cell_b`` share one ROS graph without crosstalk.  In the
# root namespace they are the absolute names of docs/architecture.md (``/left_arm/sm/state``).
def sm_topic(group: str, leaf: str) -> str:
    """``<group>/sm/<leaf>`` for request, result, state, status, structure, located."""
    return f"{group}/sm/{leaf}"


def sm_service(group: str, command: str) -> str:
    """``<group>/sm/<command>`` for pause, resume, stop, reset."""
    return f"{group}/sm/{command}"


def bridge_topic(group: str, leaf: str) -> str:
    """``<group>/bridge/<leaf>`` for command and feedback."""
    return f"{group}/bridge/{leaf}"


def tcp_pose_topic(group: str) -> str:
    return f"{group}/tcp_pose"


# The nodes of a cell: the embedded deployment, the launch files and ``launch`` give them these
# names, and the engine names a lost machine by its node.
ENGINE_NODE = "execution_engine"


def machine_node_name(group: str) -> str:
    """The node of a group's state machine."""
    return f"{group}_machine"


def bridge_node_name(backend: str) -> str:
    """The node of a bridge, from the back end's registry name (``nextage-sim`` -> ``nextage_sim_bridge``)."""
    return f"{backend.replace('-', '_')}_bridge"


ENGINE_STATUS = "execution_engine/status"
ENGINE_EVENTS = "execution_engine/events"
ENGINE_CELL = "execution_engine/cell"
JOINT_STATES = "joint_states"
# The standard visualisation topics (robot_state_publisher, tf2, diagnostic_updater use the same
# names); relative too, so a namespaced cell keeps its own -- RViz then needs ``/tf:=tf`` remaps.
ROBOT_DESCRIPTION_TOPIC = "robot_description"
TF_TOPIC = "tf"
TF_STATIC_TOPIC = "tf_static"
DIAGNOSTICS_TOPIC = "diagnostics"
SAFETY_STOP = "cell/safety_stop"
SYNC_TOPIC = "coordination/sync"
CLOCK_TOPIC = "/clock"  # absolute, as rclpy's TimeSource reads it; a launch namespace remaps it to <ns>/clock
ENGINE_SERVICES = ("start", "pause", "resume", "stop", "step", "reset", "skip")
MACHINE_SERVICES = ("pause", "resume", "stop", "reset")


def engine_service(command: str) -> str:
    return f"execution_engine/{command}"
