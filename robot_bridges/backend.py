"""The bridge port: what a robot back end must do so group machines can drive it.

A back end executes :mod:`core_functions.primitives` for one or more groups and reports where
the robot is.  It knows nothing of topics: :class:`robot_bridges.bridge_node.BridgeNode` carries
commands and feedback over the transport.  Back ends exist for the Nextage kinematic simulator,
an Adept V+ controller (TCP) and a KUKA controller over RSI (UDP).

Contract, which the bridge node and the tests rely on:

* ``execute`` runs one primitive to completion and returns its result, or raises
  :class:`BridgeError` with a :class:`FaultKind`; it never returns half-done.
* ``pause`` holds the group where it is; ``resume`` completes the *same* primitive to the same
  target; ``stop`` abandons it, and the pending ``execute`` raises ``BridgeError(STOPPED)``.
* ``set_speed_override`` plays every running and later motion at a rate in [0, 1] of its planned
  speed, on its planned path (robot_bridges/path_rate.py): 0 holds the group on the path, a rate
  above 0 again continues from there; never faster than planned.
* ``measure`` says where an idle group is now, by the robot's word: the pose a relative move
  starts from, which the group machine fixes before sending one, so that a retry is re-based on
  it and never repeats the move (docs/architecture.md, "Motions are never repeated blindly").
* Any other exception out of a back end is a bug; the bridge node still reports it as an error.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from core_functions.geometry import Pose
from core_functions.option_ranges import bounds
from core_functions.primitives import MotionResult, Primitive, PrimitiveResult
from core_functions.robots import RobotModel
from node_transport.clock import Clock

# FaultKind is defined with the wire messages: it travels in the bridge's error feedback and on
# to the engine, which decides from it alone whether a second try can succeed.
from node_transport.wire import FaultKind

__all__ = ["BackendOptions", "BridgeError", "FaultKind", "JointLimits", "RobotBackend"]

if TYPE_CHECKING:  # the cell snapshot is only a parameter type here
    from node_transport.wire import CellSnapshot


class BridgeError(Exception):
    """A primitive failed on the robot side; ``kind`` says why, the message says where."""

    def __init__(self, kind: FaultKind, message: str) -> None:
        super().__init__(f"{kind.value}: {message}")
        self.kind = kind
        self.detail = message


@dataclass(frozen=True)
class JointLimits:
    """What one group's joints may do, by the back end's own word (the limits its primitives are checked
    against): positions (rad), speeds (rad/s) and accelerations (rad/s^2), in the group's joint order.
    A FollowJointTrajectory goal (:mod:`robot_bridges.trajectory_goal`) is checked against them before
    anything moves."""

    joint_names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    velocity: tuple[float, ...]
    acceleration: tuple[float, ...]

    def __post_init__(self) -> None:
        count = len(self.joint_names)
        if not count or any(len(v) != count for v in (self.lower, self.upper, self.velocity, self.acceleration)):
            raise ValueError(f"joint limits need one value per joint of {list(self.joint_names)}")
        if not all(lo <= hi for lo, hi in zip(self.lower, self.upper)) or min(*self.velocity, *self.acceleration) <= 0:
            raise ValueError(f"joint limits of {list(self.joint_names)}: lower above upper, or a speed or acceleration not above 0")


class RobotBackend(ABC):
    """One robot controller (real or simulated) serving one or more groups."""

    #: Human-readable name for logs ("nextage_sim", "vplus 192.168.0.10:1234", ...).
    name: str = "backend"
    #: The frame poses are expressed in (the robot base; ``WAIST`` on Nextage).
    world_frame: str = "world"
    #: Whether ``pause`` and ``stop`` hold the arm inside a running motion and :meth:`joint_state` follows
    #: the arm while it moves (the Nextage simulator, KUKA RSI).  False: both only between motions (V+
    #: AdeptServer runs a motion it was sent to its end and reports the arm in its acknowledgement), so a
    #: trajectory is sent in short legs there, each ending on a point of the path.
    holds_within_motion: bool = True
    #: The clock the robot's motions run on, when it is not the bridge node's (a simulator faster than real time).
    clock: Clock | None = None
    #: The operator's speed override as a rate in [0, 1] (1: as the application wrote it).
    speed_override: float = 1.0

    @property
    @abstractmethod
    def groups(self) -> tuple[str, ...]:
        """The groups this back end drives."""

    async def start(self) -> None:
        """Connect or start the simulation; called once before the first command."""

    async def close(self) -> None:
        """Release the connection; called once at shutdown."""

    @abstractmethod
    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        """Run ``primitive`` on ``group`` to completion; raise :class:`BridgeError` on failure."""

    @abstractmethod
    async def pause(self, group: str) -> None:
        """Hold the group's motion in place (no-op when idle)."""

    @abstractmethod
    async def resume(self, group: str) -> None:
        """Continue the paused primitive to its original target."""

    @abstractmethod
    async def stop(self, group: str) -> None:
        """Abandon the group's current primitive and hold position."""

    def set_speed_override(self, rate: float) -> None:
        """Scale the running motion (and every later one) to ``rate`` of its planned speed on its path.

        A back end that plays its own trajectories changes the rate within the joints' limits; one that
        hands them to a controller asks the controller to.  The base class only keeps the value: a back
        end that does nothing more says so by overriding this (the bridge reports what it raised)."""
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"a speed override rate lies in [0, 1], got {rate!r}")
        self.speed_override = rate

    async def measure(self, group: str) -> MotionResult:
        """Where ``group`` is now: every joint of :meth:`joint_state` and the group's TCP.

        A back end whose estimate can be stale (a lost link) refreshes it from the robot first;
        raise :class:`BridgeError` when it cannot (BUSY while the group executes a primitive).
        """
        names, positions = self.joint_state()
        return MotionResult(tuple(names), tuple(positions), self.tcp_pose(group))

    @abstractmethod
    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        """Names and positions (rad) of every joint the back end knows."""

    @abstractmethod
    def tcp_pose(self, group: str) -> Pose | None:
        """The group's TCP in the world frame, or None for a group without one (torso_head)."""

    def set_cell(self, cell: CellSnapshot) -> None:  # noqa: B027 - optional hook
        """Receive the application's cell model (simulators use it for simulated vision)."""

    def joint_limits(self, group: str) -> JointLimits | None:
        """The limits of ``group``'s joints, or None when the back end does not know them (then it
        serves no FollowJointTrajectory action for the group: a goal could not be checked)."""
        return None

    def robot_description(self) -> str | None:
        """The robot's URDF text, or None when no URDF is known.

        With a URDF the bridge publishes it on ``robot_description`` and the links on ``tf``
        (:mod:`robot_bridges.robot_state`); its root link must be :attr:`world_frame`, and its
        joint names those of :meth:`joint_state`.
        """
        return None


@dataclass(frozen=True)
class BackendOptions:
    """How to reach (or simulate) a robot; each back end uses what concerns it and rejects the rest."""

    robot: RobotModel
    host: str | None = None  # a real controller's address; None: start a simulator in-process
    port: int | None = None
    rsi_listen: str | None = None  # KUKA RSI: HOST:PORT to serve a real controller on
    faults: tuple[str, ...] = ()  # fault injections for tests and demos, e.g. "right_arm:joint_limit@0.5"
    seed: int = 0
    extra: dict[str, str] = field(default_factory=dict)
    speed_override: float = 1.0  # the operator's speed override the robot starts at (a rate, 0..1): the run's and its dry run's

    def check(self, backend: str, robot: RobotModel, known_extras: Iterable[str]) -> None:
        """Refuse, rather than ignore, options meant for another robot or back end, and a seed out of its range.

        Each back end checks its numeric extras against core_functions.option_ranges as it parses them."""
        if self.robot.name != robot.name:
            raise ValueError(f"the {backend} back end drives {robot.name}, not {self.robot.name}")
        bounds("seed").check_int(f"{backend}: seed", self.seed)
        known = sorted(known_extras)
        unknown = sorted(set(self.extra) - set(known))
        if unknown:
            raise ValueError(f"{backend}: unknown option(s) {', '.join(unknown)} (known: {', '.join(known)})")
