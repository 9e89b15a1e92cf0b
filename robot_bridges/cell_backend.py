"""The ``cell`` back end: every robot of a mixed cell, each on its own back end, as one.

A cell file's ``<robot>`` elements (core_functions/cell_robots.py) name each robot's model, base
pose and back end; this builds each robot's back end from its own options, placed in the cell's
world frame (:mod:`robot_bridges.placed`).  The deployment gives each robot a bridge of its own
(:attr:`CellBackend.parts`); the checks before and around a run (measuring where every group
stands, the dry run) see the whole cell through the one object, group by group.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from core_functions.cell_robots import BACKEND_NAMES, CellNames, CellRobot, CellRobotModel
from core_functions.geometry import Pose
from core_functions.primitives import MotionResult, Primitive, PrimitiveResult
from node_transport.clock import Clock
from node_transport.wire import CellSnapshot
from robot_bridges.backend import BackendOptions, JointLimits, RobotBackend
from robot_bridges.placed import PlacedBackend
from robot_bridges.registry import check_options, create_backend


@dataclass(frozen=True)
class Part:
    """One robot of the cell and the back end that drives it (placed in the cell's world frame)."""

    robot: CellRobot
    backend: RobotBackend


#: The options of a cell's robot that are a back end's connection settings rather than its extras.
LINK_OPTIONS = ("host", "port", "rsi_listen")


def member_options(options: BackendOptions, member: CellRobot) -> BackendOptions:
    """What ``member``'s own back end is built from: its model and the options the cell gives it, ``host``,
    ``port`` and ``rsi_listen`` among them as for a robot of its own (a run's --seed carries over)."""
    extra = dict(member.options)
    link = {key: extra.pop(key) for key in LINK_OPTIONS if key in extra}
    port: int | None = None
    if "port" in link:
        try:
            port = int(link["port"])
        except ValueError:
            raise ValueError(f"robot {member.name!r}: option port must be a whole number, got {link['port']!r}") from None
    return BackendOptions(robot=member.model, host=link.get("host"), port=port, rsi_listen=link.get("rsi_listen"), seed=options.seed, extra=extra)


def cell_members(options: BackendOptions) -> tuple[CellRobot, ...]:
    robot = options.robot
    if not isinstance(robot, CellRobotModel) or not robot.members:
        raise ValueError(f"the cell back end drives the robots a cell lists (robot=\"cell\"), not {robot.name}")
    return robot.members


def parse_options(options: BackendOptions, speed: float = 1.0) -> None:
    """Each robot's options as its own back end checks them; ValueError naming the robot and the option."""
    if options.extra or options.host or options.rsi_listen or options.faults:
        raise ValueError("the cell back end takes its robots' options from the cell's <robot> elements (<option name= value=/>), not from the command line")
    for member in cell_members(options):
        if member.backend not in BACKEND_NAMES:
            raise ValueError(f"robot {member.name!r}: unknown back end {member.backend!r}")
        try:
            check_options(member.backend, member_options(options, member), speed)
        except (KeyError, ValueError) as error:
            raise ValueError(f"robot {member.name!r} ({member.backend}): {error}") from None


def renamed_observer(observer: Any, names: CellNames) -> Any:
    """``observer`` (a simulator's planned motions: its groups, its joints, then the motion) told the cell's
    group and joint names, as the cell's collision model names them."""
    if names.identity:
        return observer

    def observe(groups: frozenset[str], joints: tuple[str, ...], *motion: Any) -> None:
        observer(frozenset(names.group(g) for g in groups), tuple(names.joint(j) for j in joints), *motion)
    observe.inner = observer  # type: ignore[attr-defined]  # what the getter hands back
    return observe


class CellBackend(RobotBackend):
    """Every robot's back end; a group's calls go to the robot it belongs to."""

    def __init__(self, parts: tuple[Part, ...]) -> None:
        self.parts = parts
        self.name = "cell (" + ", ".join(p.backend.name for p in parts) + ")"
        self.world_frame = "world"
        self.holds_within_motion = all(p.backend.holds_within_motion for p in parts)
        self._by_group = {g: p.backend for p in parts for g in p.backend.groups}

    @property
    def groups(self) -> tuple[str, ...]:
        return tuple(self._by_group)

    def _simulators_with(self, attribute: str) -> list[RobotBackend]:
        """The robots' own back ends (a placed one's inner) that have ``attribute``: what a dry run hooks into."""
        inner = [part.backend.inner if isinstance(part.backend, PlacedBackend) else part.backend for part in self.parts]
        return [backend for backend in inner if attribute in vars(backend)]

    @property
    def motion_observer(self) -> Any:
        """The dry run's observer of planned motions, handed to every simulator that shows them (told the
        cell's group and joint names, which the cell's collision model uses)."""
        observers = [getattr(b, "motion_observer") for b in self._simulators_with("motion_observer")]
        return getattr(observers[0], "inner", observers[0]) if observers else None

    @motion_observer.setter
    def motion_observer(self, observer: Any) -> None:
        for part in self.parts:
            backend = part.backend.inner if isinstance(part.backend, PlacedBackend) else part.backend
            if "motion_observer" in vars(backend):
                setattr(backend, "motion_observer", renamed_observer(observer, part.robot.names) if observer is not None else None)

    @property
    def collisions(self) -> Any:
        """A simulator's own collision check (its robot alone); the dry run switches them off (None) and sweeps
        the whole cell's model instead."""
        checks = [getattr(b, "collisions") for b in self._simulators_with("collisions")]
        return next((c for c in checks if c is not None), None)

    @collisions.setter
    def collisions(self, scene: Any) -> None:
        for backend in self._simulators_with("collisions"):
            setattr(backend, "collisions", scene)

    def of(self, group: str) -> RobotBackend:
        return self._by_group[group]

    async def start(self) -> None:
        for part in self.parts:
            await part.backend.start()

    async def close(self) -> None:
        for part in reversed(self.parts):
            await part.backend.close()

    async def execute(self, group: str, primitive: Primitive) -> PrimitiveResult:
        result = await self.of(group).execute(group, primitive)
        return self._whole(result) if isinstance(result, MotionResult) else result

    def _whole(self, result: MotionResult) -> MotionResult:
        names, positions = self.joint_state()
        return replace(result, joint_names=names, positions=positions)

    async def pause(self, group: str) -> None:
        await self.of(group).pause(group)

    async def resume(self, group: str) -> None:
        await self.of(group).resume(group)

    async def stop(self, group: str) -> None:
        await self.of(group).stop(group)

    async def measure(self, group: str) -> MotionResult:
        return self._whole(await self.of(group).measure(group))

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names: list[str] = []
        positions: list[float] = []
        for part in self.parts:
            n, p = part.backend.joint_state()
            names.extend(n)
            positions.extend(p)
        return tuple(names), tuple(positions)

    def tcp_pose(self, group: str) -> Pose | None:
        return self.of(group).tcp_pose(group)

    def set_cell(self, cell: CellSnapshot) -> None:
        for part in self.parts:
            part.backend.set_cell(cell)

    def set_speed_override(self, rate: float) -> None:
        """One override for the cell: every robot's back end plays its motions at it."""
        super().set_speed_override(rate)
        for part in self.parts:
            part.backend.set_speed_override(rate)

    def joint_limits(self, group: str) -> JointLimits | None:
        return self.of(group).joint_limits(group)


async def create(clock: Clock, options: BackendOptions) -> CellBackend:
    """Registry factory (``cell``): each robot's back end, built as its own factory builds it, placed."""
    parts: list[Part] = []
    try:
        for member in cell_members(options):
            try:
                inner = await create_backend(member.backend, clock, member_options(options, member))
            except (KeyError, ValueError) as error:  # one line naming the robot of the cell whose options they are
                raise ValueError(f"robot {member.name!r} ({member.backend}): {error.args[0] if error.args else error}") from None
            # placed even at the world's origin and under its own names: in a cell every robot's URDF and tf hang from the world
            parts.append(Part(member, PlacedBackend(inner, member.base, member.name, member.names, member.model.cameras)))
    except BaseException:
        for part in reversed(parts):
            await part.backend.close()
        raise
    return CellBackend(tuple(parts))
