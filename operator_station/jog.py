"""Hold-to-move jogging of one group: a joint, or the TCP along or about an axis of the world, the tool or a cell frame.

A person holding a button on a page is the only thing keeping the arm moving, so the jog is built the other
way round from a run: it moves only while it keeps hearing from the page, and everything else stops it.

* **Through the back end, in legs.**  A jog is a chain of ordinary primitives on the group -- ``MoveJoints``
  to a point further along the joint, ``MoveRelative`` along the axis -- at a reduced speed set first with
  ``SetSpeed``.  So the back end plans and checks each leg as it does any motion of a run (its joint and
  Cartesian limits, its reach, the simulator's own collision sweep) and refuses what it would refuse there.
  A back end that holds inside a motion (the Nextage simulator, KUKA RSI) gets legs of :attr:`JogSettings.leg`
  seconds of travel and is stopped inside one; V+ runs a motion to its end, so it gets legs of
  :attr:`JogSettings.short_leg` seconds and stops at the end of the leg under way.
* **Capped speed.**  At most :data:`MAX_SPEED` (10 %) of each joint's speed limit, and the TCP of a Cartesian jog
  at most :data:`MAX_CARTESIAN` (50 mm/s) whatever the robot's own TCP limit; a page may ask for less.  The back
  ends' speed fraction scales time, acceleration too, so where a back end replays trajectories and stops inside
  them a joint jog is a trajectory of its own (:func:`ramp`: full acceleration up to the cap).
* **Dead man.**  The page beats every ~100 ms while the button is held; a release, a closed connection or
  :attr:`JogSettings.lease` seconds without a beat stops the group (``stop``: inside the motion at the back
  end's next control period).  The watch sleeps until the lease ends, not a period longer.
* **Collisions ahead.**  Every control period the watch looks one look-ahead down the path the arm is on (its
  joints' motion over the last period, extrapolated) in the collision scene of the dry run and the simulator
  (the robot's links, tools and the cell's boxes) with :attr:`JogSettings.clearance`: a pair of bodies that
  would come closer than that, and closer than they are, stops the jog and is named.  A jog may move away
  from an obstacle it is near, never towards it.

The jogger runs on whatever loop and clock it is given: the station gives it the wall clock on a thread of its
own (:mod:`operator_station.jog_station`), the tests a simulated clock.
"""
from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Collection, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Literal

import numpy as np

from core_functions.geometry import Pose
from core_functions.motion_profile import TcpLimits
from core_functions.primitives import ExecuteTrajectory, MoveJoints, MoveRelative, Primitive, SetSpeed
from core_functions.robots import RobotModel
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind, RobotBackend
from robot_bridges.collision import CollisionScene
from operator_station.jog_cartesian import ResolvedRates

log = logging.getLogger(__name__)

#: The fastest a jog moves a joint: this fraction of its speed limit.
MAX_SPEED = 0.10
#: The fastest a jog moves the TCP (m/s), whatever the robot's own TCP limit.
MAX_CARTESIAN = 0.05
#: The Cartesian axes: along and about x, y, z of the chosen frame.
AXES = ("x", "y", "z", "rx", "ry", "rz")
#: Frames a Cartesian jog may be in besides the cell's own.
WORLD, TOOL = "world", "tool"
#: s: the control period assumed for a back end that does not state its own.
DEFAULT_PERIOD = 0.01
#: rad: a joint this close to its limit is at it (a jog towards it is refused).
AT_LIMIT = 1e-4
#: s between two states sent to the page while the arm moves (its joints and TCP follow the arm).
SHOW_EVERY = 0.1
#: Times a leg the back end refuses before moving (out of reach, a joint limit on the way) is halved before
#: the jog says it cannot go on.
HALVINGS = 5


@dataclass(frozen=True)
class JogSettings:
    """How a station jogs; :data:`MAX_SPEED` and :data:`MAX_CARTESIAN` bound every field that is a speed."""

    speed: float = MAX_SPEED  # fraction of each joint's (and the TCP's) speed limit
    cartesian_speed: float = MAX_CARTESIAN  # m/s, at most
    lease: float = 0.3  # s a heartbeat keeps the jog going: three beats of the page's 100 ms
    clearance: float = 0.002  # m two bodies keep while jogging
    leg: float = 1.0  # s of travel per primitive where the back end stops inside a motion
    short_leg: float = 0.1  # s of travel per primitive where it does not (V+)

    def __post_init__(self) -> None:
        if not 0.0 < self.speed <= MAX_SPEED:
            raise ValueError(f"jog speed must be in (0, {MAX_SPEED:.0%}] of the joint limits, got {self.speed!r}")
        if not 0.0 < self.cartesian_speed <= MAX_CARTESIAN:
            raise ValueError(f"jog Cartesian speed must be in (0, {MAX_CARTESIAN * 1000:.0f}] mm/s, got {self.cartesian_speed * 1000!r} mm/s")
        if not 0.05 <= self.lease <= 2.0:
            raise ValueError(f"jog heartbeat lease must be in [0.05, 2] s, got {self.lease!r}")
        if not 0.0 <= self.clearance <= 0.1:
            raise ValueError(f"jog clearance must be in [0, 0.1] m, got {self.clearance!r}")
        if not (0.0 < self.short_leg <= self.leg <= 5.0):
            raise ValueError(f"jog legs must be 0 < short_leg <= leg <= 5 s, got {self.short_leg!r}, {self.leg!r}")

    def slower(self, percent: float | None) -> JogSettings:
        """These settings at ``percent`` of the joint limits instead, never faster than they are."""
        if percent is None:
            return self
        if not (isinstance(percent, (int, float)) and 1.0 <= percent <= 100.0):
            raise ValueError(f"jog: speed must be a percentage from 1 to {self.speed * 100:g}, got {percent!r}")
        fraction = min(self.speed, percent / 100.0)
        return replace(self, speed=fraction, cartesian_speed=min(self.cartesian_speed, MAX_CARTESIAN * fraction / MAX_SPEED))


@dataclass(frozen=True)
class JogRequest:
    """One press of a jog button: which group, which joint or axis, which way, in which frame."""

    group: str
    mode: Literal["joint", "cartesian"]
    axis: str  # a joint of the group, or one of AXES
    direction: int  # +1 or -1
    frame: str = WORLD  # Cartesian: world, tool or a frame of the cell
    speed: float | None = None  # percent of the joint limits, at most the station's

    def describe(self) -> str:
        sign = "+" if self.direction > 0 else "-"
        return f"{self.group} {self.axis}{sign}" + (f" in {self.frame}" if self.mode == "cartesian" else "")


def parse_request(body: Mapping[str, Any], robot: RobotModel, frames: Collection[str]) -> JogRequest:
    """The page's ``{group, mode, axis, direction, frame, speed}``; ValueError, one line naming the field."""
    group = body.get("group")
    if group not in robot.group_names:
        raise ValueError(f"jog: group must be one of {', '.join(robot.group_names)}, got {group!r}")
    mode = body.get("mode")
    if mode not in ("joint", "cartesian"):
        raise ValueError(f"jog: mode must be joint or cartesian, got {mode!r}")
    axis = body.get("axis")
    joints = robot.group(group).joint_names
    if mode == "joint" and axis not in joints:
        raise ValueError(f"jog: axis must be a joint of {group} ({', '.join(joints)}), got {axis!r}")
    if mode == "cartesian" and axis not in AXES:
        raise ValueError(f"jog: axis must be one of {', '.join(AXES)}, got {axis!r}")
    direction = body.get("direction")
    if direction not in (1, -1) or isinstance(direction, bool):
        raise ValueError(f"jog: direction must be 1 or -1, got {direction!r}")
    frame = body.get("frame", WORLD)
    if mode == "cartesian" and frame not in (WORLD, TOOL) and frame not in frames:
        raise ValueError(f"jog: frame must be world, tool or a frame of the cell, got {frame!r}")
    speed = body.get("speed")
    if speed is not None and (isinstance(speed, bool) or not isinstance(speed, (int, float))):
        raise ValueError(f"jog: speed must be a percentage, got {speed!r}")
    return JogRequest(str(group), mode, str(axis), int(direction), str(frame), None if speed is None else float(speed))


@dataclass
class JogState:
    """What the page shows of the jog: whether it moves, and the one line saying why it stopped or was refused."""

    moving: bool = False
    request: dict[str, Any] | None = None
    reason: str = ""  # why the last jog stopped, or was refused
    refused: bool = False  # the last jog was refused or stopped by a check (not by the person)
    stop_asked: float | None = None  # clock time the stop was asked (release, lapse, check)
    stopped_at: float | None = None  # clock time the group was still again
    travel_after_stop: float = 0.0  # rad: the most any joint of the group moved between the two
    joints: dict[str, float] = field(default_factory=dict)
    tcp: list[float] | None = None  # the group's TCP in the world: x y z (m), roll pitch yaw (rad)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


class Jogger:
    """Jogs the groups of one back end, one jog at a time, on the loop it is used from."""

    def __init__(
        self, backend: RobotBackend, clock: Clock, robot: RobotModel, settings: JogSettings = JogSettings(), *,
        frames: Callable[[str], Pose] | None = None, scene: CollisionScene | None = None,
        on_change: Callable[[JogState], None] | None = None,
    ) -> None:
        """``frames``: a cell frame's pose in the world (KeyError for none); ``scene``: the collision scene with
        the cell set, its margin the clearance (None: the back end's own checks only)."""
        self.backend = backend
        self.clock = clock
        self.robot = robot
        self.settings = settings
        self.frames = frames
        self.scene = scene
        self.on_change = on_change
        self.state = JogState()
        self._drive: asyncio.Task[None] | None = None
        self._watch: asyncio.Task[None] | None = None
        self._halting: asyncio.Task[None] | None = None
        self._deadline = 0.0
        self._group = ""
        self._halted = False
        self._stop_q: np.ndarray | None = None
        self._profiles = True  # jogs as trajectories of their own (full acceleration, capped speed) where taken
        self._rates = ResolvedRates(scene) if scene is not None else None
        names = backend.joint_state()[0]
        self._order = [names.index(n) for n in scene.joint_names] if scene is not None else []

    @property
    def period(self) -> float:
        """s: the back end's control period, the unit of every stop's promise."""
        return float(getattr(self.backend, "control_period", DEFAULT_PERIOD))

    @property
    def moving(self) -> bool:
        return self._drive is not None and not self._drive.done()

    # ------------------------------------------------------------------ the page's side
    async def start(self, request: JogRequest) -> tuple[bool, str]:
        """Start jogging (a jog going on stops first); False and the one-line reason when refused."""
        await self.stop("another jog button")
        settings = self.settings.slower(request.speed)
        try:
            first = self._leg(request, settings, 1.0)
            self._check_ahead(self._joints(), self._first_step(request, settings))
        except (ValueError, KeyError) as refusal:
            self.state = JogState(False, asdict(request), str(refusal).strip("'\""), True)
            self.observe(request.group)
            self._changed()
            return False, self.state.reason
        self._group, self._halted, self._stop_q = request.group, False, None
        self._deadline = self.clock.now() + settings.lease
        self.state = JogState(True, asdict(request), "", False)
        self.observe(request.group)
        self._drive = asyncio.get_running_loop().create_task(self._run(request, settings, first))
        self._watch = asyncio.get_running_loop().create_task(self._guard(settings))
        self._changed()
        return True, f"jogging {request.describe()}"

    def beat(self) -> None:
        """The button is still held: the jog may go on for another lease."""
        if self.moving and not self._halted:
            self._deadline = self.clock.now() + self.settings.lease

    async def stop(self, reason: str, refused: bool = False) -> None:
        """Stop the jog going on (nothing when none is): the group holds where it is."""
        if not self.moving:
            return
        self._halt(reason, refused)
        drive = self._drive
        assert drive is not None
        await asyncio.wait({drive}, timeout=max(2.0, 20 * self.period))

    # ------------------------------------------------------------------ the motion
    async def _run(self, request: JogRequest, settings: JogSettings, first: Primitive) -> None:
        group, leg, scale = request.group, first, 1.0
        try:
            await self.backend.execute(group, SetSpeed(1.0 if isinstance(leg, ExecuteTrajectory) else self._fraction(request, settings)))
            while not self._halted:
                before, began = self._joints(), self.clock.now()
                try:
                    await self.backend.execute(group, leg)
                except BridgeError as error:
                    if self._halted:
                        break
                    unmoved = np.allclose(before, self._joints(), atol=1e-9)
                    if unmoved and isinstance(leg, ExecuteTrajectory) and error.kind is FaultKind.UNSUPPORTED:
                        self._profiles = False  # this back end replays no trajectory: legs it plans itself, time-scaled
                        await self.backend.execute(group, SetSpeed(self._fraction(request, settings)))
                    elif unmoved and scale > 0.5 ** HALVINGS and error.kind in (FaultKind.UNREACHABLE, FaultKind.JOINT_LIMIT):
                        scale /= 2.0  # the plan failed before moving: try a shorter leg to go as far as it can
                    else:
                        self._halt(f"jog {request.describe()} stopped: {error.detail}", True)
                        break
                else:
                    # A leg done sooner than its share of the jog's speed (a controller faster than the cap asked):
                    # wait the rest, so that on average the TCP and joints never go faster than the cap.
                    due = began + self._leg_time(settings) * scale
                    scale = 1.0
                    while due - self.clock.now() > 1e-9 and not self._halted:
                        await self.clock.sleep(min(due - self.clock.now(), self.period))
                try:
                    leg = self._leg(request, settings, scale)
                except (ValueError, KeyError) as refusal:
                    self._halt(f"jog {request.describe()} stopped: {str(refusal).strip(chr(39))}", True)
        except BridgeError as error:  # the speed itself refused, or a stop between legs
            if not self._halted:
                self._halt(f"jog {request.describe()} stopped: {error.detail}", True)
        except Exception as error:  # noqa: BLE001 - the page must hear of it; the task must not die silently
            log.exception("the jog failed")
            self._halt(f"jog {request.describe()} failed: {type(error).__name__}: {error}", True)
        finally:
            if self._halting is not None:
                await asyncio.shield(self._halting)
            if self._watch is not None:
                self._watch.cancel()
            end = self._joints()
            self.state.moving = False
            self.state.stopped_at = self.clock.now()
            self.observe(group)
            if self._stop_q is not None:
                idx = self._group_index(group)
                self.state.travel_after_stop = float(np.max(np.abs(end[idx] - self._stop_q[idx]))) if len(idx) else 0.0
            self._changed()

    def _halt(self, reason: str, refused: bool = False) -> None:
        """Ask the back end to stop the group now (once); the reason is what the page shows."""
        if self._halted:
            return
        self._halted = True
        self.state.reason, self.state.refused = reason, refused
        self.state.stop_asked = self.clock.now()
        self._stop_q = self._joints()
        self._halting = asyncio.get_running_loop().create_task(self.backend.stop(self._group))

    async def _guard(self, settings: JogSettings) -> None:
        """The dead man and the look-ahead: wakes every control period, and exactly when the lease ends."""
        q, at = self._joints(), self.clock.now()
        shown = at
        lookahead = 2.0 * self.period if self.backend.holds_within_motion else settings.short_leg + self.period
        while not self._halted:
            now = self.clock.now()
            if now >= self._deadline - 1e-9:
                self._halt(f"jog stopped: no heartbeat from the page for {settings.lease:.2f} s (connection lost or page hidden)", True)
                return
            current = self._joints()
            if now > at:
                ahead = current + (current - q) * (lookahead / (now - at))
                try:
                    self._check_ahead(current, ahead)
                except ValueError as problem:
                    self._halt(str(problem), True)
                    return
            q, at = current, now
            if now >= shown + SHOW_EVERY - 1e-9:  # the page follows the arm while it moves
                shown = now
                self.observe(self._group)
                self._changed()
            await self.clock.sleep(min(self.period, self._deadline - now))

    def _check_ahead(self, now: np.ndarray, ahead: np.ndarray | None) -> None:
        """ValueError naming the pair of bodies the jog would bring closer than the clearance, and closer than now."""
        if self.scene is None or ahead is None:
            return
        near = {(c.a.label(), c.b.label()): c.distance for c in self.scene.contacts(now[self._order])}
        for contact in sorted(self.scene.contacts(ahead[self._order]), key=lambda c: c.distance):
            if contact.distance < near.get((contact.a.label(), contact.b.label()), math.inf) - 1e-7:
                gap = "touch" if contact.distance <= 0 else f"come {contact.distance * 1000:.1f} mm apart"
                raise ValueError(f"jog stopped before a collision: {contact.a.label()} and {contact.b.label()} would {gap}, "
                                 f"within the jog's {self.scene.margin * 1000:.0f} mm clearance")

    # ------------------------------------------------------------------ legs
    def _fraction(self, request: JogRequest, settings: JogSettings) -> float:
        """The SetSpeed fraction: the joint share, and for the TCP no more than the Cartesian speed allows."""
        if request.mode == "joint":
            return settings.speed
        return min(settings.speed, settings.cartesian_speed / self._tcp_limits().linear_velocity)

    def _tcp_limits(self) -> TcpLimits:
        limits = getattr(self.backend, "cartesian_limits", None)
        return limits if isinstance(limits, TcpLimits) else TcpLimits()

    def _leg_time(self, settings: JogSettings) -> float:
        return settings.leg if self.backend.holds_within_motion else settings.short_leg

    def _leg(self, request: JogRequest, settings: JogSettings, scale: float) -> Primitive:
        """The next primitive of the jog; ValueError (one line) when the group cannot go that way at all."""
        seconds = self._leg_time(settings) * scale
        if request.mode == "joint":
            return self._joint_leg(request, settings, seconds)
        tcp_now = self.backend.tcp_pose(request.group)
        if tcp_now is None:
            raise ValueError(f"jog: {request.group} has no TCP: jog its joints")
        fraction = self._fraction(request, settings)
        limits = self._tcp_limits()
        axis = AXES.index(request.axis) % 3
        if request.frame == TOOL:
            unit, reference = tuple(1.0 if k == axis else 0.0 for k in range(3)), "tool"
        else:
            rotation = np.eye(3) if request.frame == WORLD else self._frame(request.frame).matrix()[:3, :3]
            unit, reference = tuple(float(v) for v in rotation[:, axis]), "world"
        sign = float(request.direction)
        rates = self._rates_for(request.group, tcp_now)
        if rates is not None:  # a leg of the jog's own: at speed within a fraction of a second
            world = np.array(unit) if reference == "world" else tcp_now.matrix()[:3, axis]
            names, positions = self.backend.joint_state()
            q = np.array(positions, dtype=float)[self._order]
            joints = self.robot.group(request.group).joint_names
            limits_j = self.backend.joint_limits(request.group)
            assert limits_j is not None  # _rates_for checked it
            leg = rates.plan(request.group, q, joints, limits_j, sign * world, request.axis.startswith("r"), settings.speed,
                             settings.cartesian_speed, limits, seconds, self.period)
            return ExecuteTrajectory("jog", joints, leg.points, leg.times)
        if request.axis.startswith("r"):
            half = 0.5 * sign * fraction * limits.angular_velocity * seconds
            s = math.sin(half)
            delta = Pose(0.0, 0.0, 0.0, unit[0] * s, unit[1] * s, unit[2] * s, math.cos(half))
        else:
            length = sign * fraction * limits.linear_velocity * seconds
            delta = Pose(unit[0] * length, unit[1] * length, unit[2] * length)
        return MoveRelative(delta, reference, "linear")  # type: ignore[arg-type] - reference is world or tool

    def _rates_for(self, group: str, tcp: Pose) -> ResolvedRates | None:
        """The planner of the jog's own Cartesian legs, where the back end replays trajectories and stops inside
        them and the scene's model puts the TCP where the back end does; None: the back end's own legs."""
        if not (self._profiles and self.backend.holds_within_motion and self._rates is not None and self.backend.joint_limits(group) is not None):
            return None
        q = self._joints()[self._order]
        return self._rates if self._rates.agrees(group, q, tcp.position) else None

    def _frame(self, name: str) -> Pose:
        if self.frames is None:
            raise ValueError(f"jog: no cell model to find frame {name!r} in")
        try:
            return self.frames(name)
        except KeyError:
            raise ValueError(f"jog: frame {name!r} is not in the cell model") from None

    def _joint_leg(self, request: JogRequest, settings: JogSettings, seconds: float) -> MoveJoints | ExecuteTrajectory:
        names, positions = self.backend.joint_state()
        value = positions[names.index(request.axis)]
        limits = self.backend.joint_limits(request.group)
        speed = 1.0
        room = math.inf
        if limits is not None:
            k = limits.joint_names.index(request.axis)
            speed = limits.velocity[k]
            bound = limits.upper[k] if request.direction > 0 else limits.lower[k]
            room = abs(bound - value)
            if room <= AT_LIMIT or (bound - value) * request.direction < 0:
                side = "upper" if request.direction > 0 else "lower"
                raise ValueError(f"jog: {request.axis} is at its {side} limit ({bound:.4f} rad, {math.degrees(bound):.2f} deg): "
                                 "it goes no further that way")
        step = min(settings.speed * speed * seconds, room)
        joints = self.robot.group(request.group).joint_names  # every joint of the group: V+ takes whole-arm moves only
        here = tuple(positions[names.index(n)] for n in joints)
        k = joints.index(request.axis)
        if self._profiles and self.backend.holds_within_motion and limits is not None:
            times, path = ramp(step, settings.speed * speed, limits.acceleration[limits.joint_names.index(request.axis)], self.period)
            points = tuple(tuple(here[i] + request.direction * d if i == k else here[i] for i in range(len(joints))) for d in path)
            return ExecuteTrajectory("jog", joints, points, times)
        return MoveJoints(tuple(here[i] + request.direction * step if i == k else here[i] for i in range(len(joints))), joints)

    def _first_step(self, request: JogRequest, settings: JogSettings) -> np.ndarray | None:
        """Where a joint jog is one look-ahead from now (None for a Cartesian one: its path is the back end's)."""
        if request.mode != "joint":
            return None
        names = self.backend.joint_state()[0]
        ahead = self._joints()
        limits = self.backend.joint_limits(request.group)
        speed = limits.velocity[limits.joint_names.index(request.axis)] if limits is not None else 1.0
        ahead[names.index(request.axis)] += request.direction * settings.speed * speed * 2.0 * max(self.period, 0.01)
        return ahead

    # ------------------------------------------------------------------ helpers
    def _joints(self) -> np.ndarray:
        return np.array(self.backend.joint_state()[1], dtype=float)

    def _group_index(self, group: str) -> list[int]:
        names = self.backend.joint_state()[0]
        return [names.index(n) for n in self.robot.group(group).joint_names if n in names]

    def observe(self, group: str) -> None:
        """The group's joints and TCP now, into the state the page shows."""
        self.state.joints = self._group_joints(group)
        tcp = self.backend.tcp_pose(group)
        self.state.tcp = None if tcp is None else [*tcp.position, *tcp.rpy()]

    def _group_joints(self, group: str) -> dict[str, float]:
        names, positions = self.backend.joint_state()
        wanted = set(self.robot.group(group).joint_names)
        return {n: float(p) for n, p in zip(names, positions) if n in wanted}

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change(self.state)


def ramp(distance: float, speed: float, acceleration: float, period: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Times and distances of a joint going ``distance`` from rest to rest: at its full ``acceleration`` up to
    ``speed`` (the jog's cap), on at it, and down again, sampled every ``period`` -- a joint jog at speed within a
    fraction of a second, where a time-scaled move (the back ends' speed fraction) would take seconds to get there."""
    cruise_from = speed / acceleration
    if distance < speed * cruise_from:  # too short to reach the speed: a triangle
        cruise_from = math.sqrt(distance / acceleration)
        speed = acceleration * cruise_from
    total = 2.0 * cruise_from + (distance - speed * cruise_from) / speed
    count = max(1, math.ceil(total / period - 1e-9))
    times = tuple(min(i * period, total) for i in range(count + 1))

    def at(t: float) -> float:
        if t <= cruise_from:
            return 0.5 * acceleration * t * t
        if t <= total - cruise_from:
            return 0.5 * acceleration * cruise_from ** 2 + speed * (t - cruise_from)
        left = total - t
        return distance - 0.5 * acceleration * left * left

    return times, tuple(min(distance, max(0.0, at(t))) for t in times)
