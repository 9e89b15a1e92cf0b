"""CoreFunctions: the functions every application can call, each a short sequence of primitives.

Every catalog function is a generator method: it yields primitives one at a time and receives
each primitive's result back (``result = yield primitive``), so a skill can use what the robot
measured -- a vision correction feeding the next move.  The group machine drives the generator:
each yielded primitive becomes one Ready -> <state> -> Ready cycle.  Arguments arrive already
parsed and checked by the catalog (:mod:`core_functions.catalog`), in SI units.

Application libraries (``app_functions``) inherit from :class:`CoreFunctions`, as in the paper
(Figure 5), and combine these building blocks into process skills.
"""
from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any

from core_functions.catalog import MEASURE_OUTCOMES, VISION_OUTCOMES, Hold, ParamSpec, ParamType, skill
from core_functions.cell_index import CellIndex
from core_functions.geometry import Pose
from core_functions.primitives import (
    END_EFFECTOR_ACTIONS,
    Dwell,
    EndEffector,
    EndEffectorAction,
    ExecuteTrajectory,
    FullBodyMove,
    MasterSlaveMove,
    MoveCartesian,
    MoveJoints,
    MoveRelative,
    Primitive,
    RecordTrajectory,
    SetOutput,
    SetSpeed,
    TrajectoryResult,
    Vision,
    VisionResult,
    WaitInput,
)
from core_functions.robots import RobotModel
from core_functions.trajectory_store import TrajectoryStore

#: What a catalog function returns: primitives out, their results in.
Skill = Generator[Primitive, Any, None]

ANY_GROUP = ("arm", "torso_head")

_REACH_DISTANCE = ParamSpec(
    "distance", ParamType.NUMBER, "approach and retreat distance along the target's z axis", unit="m", default="0.05", minimum=0.0, maximum=0.5
)
_INTERPOLATION = ParamSpec(
    "interpolation", ParamType.CHOICE, "ptp: joint-interpolated (fastest); linear: straight TCP line", default="ptp", choices=("ptp", "linear")
)
_SIGNAL_VALUE = ParamSpec("value", ParamType.NUMBER, "1 or 0 for a digital signal, a number for a numeric one", unit="", minimum=-1e9, maximum=1e9)
_OVERWRITE = ParamSpec(
    "overwrite", ParamType.BOOLEAN, "true: replace a trajectory already recorded under this name (otherwise that is an error)", default="false"
)


class OutOfRange(ValueError):
    """A value a function measured lies outside the range it checks: the function ends with the outcome
    ``out_of_range`` (an error where no ``<if>`` tests it), the message saying what was measured."""


@dataclass
class SkillContext:
    """What a group's functions instance knows of its world."""

    group: str
    robot: RobotModel
    cell: CellIndex | None
    trajectories: TrajectoryStore
    now: Callable[[], float]
    #: Results of the last vision measurement (``measure``), for skills that loop on it.
    measurements: dict[str, float] = field(default_factory=dict)


class CoreFunctions:
    """The robot API of one group (paper: core functions)."""

    def __init__(self, context: SkillContext) -> None:
        self.ctx = context

    # --------------------------------------------------------------------------- helpers
    @property
    def cell(self) -> CellIndex:
        if self.ctx.cell is None:
            raise LookupError(f"{self.ctx.group}: this function needs a cell model, and the application has none")
        return self.ctx.cell

    def resolve(self, target: str | Pose) -> Pose:
        """A target param (frame name or literal pose) as a world pose, using vision corrections."""
        return target if isinstance(target, Pose) else self.cell.pose(target)

    def camera(self) -> str:
        return self.ctx.robot.group(self.ctx.group).camera

    def group_joint_pose(self, name: str) -> tuple[tuple[str, ...], tuple[float, ...]]:
        """This group's joints in a named pose (robot pose, or a cell joint pose for the robot or the group)."""
        group = self.ctx.robot.group(self.ctx.group)
        pose = self.ctx.robot.poses.get(name)
        if pose is None:
            pose = self.cell.joint_pose(name)
        missing = [j for j in group.joint_names if j not in pose]
        if missing:
            raise LookupError(f"joint pose {name!r} has no value for {', '.join(missing)} of {self.ctx.group}")
        return group.joint_names, tuple(pose[j] for j in group.joint_names)

    def whole_robot_pose(self, name: str) -> tuple[tuple[str, ...], tuple[float, ...]]:
        pose = self.ctx.robot.poses.get(name)
        if pose is None:
            pose = self.cell.joint_pose(name)
        names = self.ctx.robot.joint_names
        missing = [j for j in names if j not in pose]
        if missing:
            raise LookupError(f"joint pose {name!r} is not a whole-robot pose: it lacks {', '.join(missing)}")
        return names, tuple(pose[j] for j in names)

    def reach_in(self, target: str | Pose, distance: float, what: str, action: EndEffectorAction) -> Skill:
        """Approach ``distance`` before the target along its z, go straight in, act, come straight out."""
        pose = self.resolve(target)
        label = target if isinstance(target, str) else "part"
        yield MoveCartesian(pose.offset_local(dz=-distance), "ptp", frame=f"{label} approach")
        yield MoveCartesian(pose, "linear", frame=f"{label} {what}")
        yield EndEffector(action)
        yield MoveCartesian(pose.offset_local(dz=-distance), "linear", frame=f"{label} retreat")

    def locate_frame(self, target: str, camera: str = "") -> Skill:
        """Locate ``target`` by vision and record the correction (a building block for skills)."""
        result: VisionResult = yield Vision("locate", target=target, nominal=self.cell.nominal(target), camera=camera or self.camera())
        if result.pose is None:
            raise LookupError(f"vision found no pose for {target!r}")
        self.cell.correct(target, result.pose)

    # ---------------------------------------------------------------------------- motion
    @skill(
        ParamSpec("joints", ParamType.JOINTS, "one value per joint of the group, in the robot's joint order", unit="rad"),
        groups=ANY_GROUP,
        states=("Motion",),
    )
    def move_joints(self, joints: tuple[float, ...]) -> Skill:
        """Articular move of the group's joints to absolute positions (all joints arrive together)."""
        names = self.ctx.robot.group(self.ctx.group).joint_names
        yield MoveJoints(positions=joints, joint_names=names)

    @skill(
        ParamSpec("pose", ParamType.JOINT_POSE, "a named joint pose: robot poses (Nextage: initial, off) or a <joint_pose> of the cell"),
        groups=ANY_GROUP,
        states=("Motion",),
    )
    def move_to_joint_pose(self, pose: str) -> Skill:
        """Articular move of the group to its joints in a named pose (e.g. the robot's initial pose)."""
        names, values = self.group_joint_pose(pose)
        yield MoveJoints(positions=values, joint_names=names)

    @skill(
        ParamSpec("target", ParamType.TARGET, "a cell frame name, or x,y,z,roll,pitch,yaw in the world frame", unit="m, rad"),
        _INTERPOLATION,
        states=("Motion",),
    )
    def move_to(self, target: str | Pose, interpolation: str = "ptp") -> Skill:
        """Move the TCP to a frame of the cell (its last vision-corrected pose, if located) or to a literal pose."""
        yield MoveCartesian(self.resolve(target), interpolation, frame=target if isinstance(target, str) else "")  # type: ignore[arg-type]

    @skill(
        ParamSpec("target", ParamType.TARGET, "a cell frame name, or x,y,z,roll,pitch,yaw in the world frame", unit="m, rad"),
        ParamSpec("distance", ParamType.NUMBER, "how far back along the target's z axis to stop", unit="m", default="0.05", minimum=0.0, maximum=1.0),
        _INTERPOLATION,
        states=("Motion",),
    )
    def approach(self, target: str | Pose, distance: float = 0.05, interpolation: str = "ptp") -> Skill:
        """Move the TCP to a point ``distance`` before the target along its z axis (the tool approaches along +z)."""
        pose = self.resolve(target).offset_local(dz=-distance)
        yield MoveCartesian(pose, interpolation, frame=f"{target}-{distance:g}m" if isinstance(target, str) else "")  # type: ignore[arg-type]

    @skill(
        ParamSpec("dx", ParamType.NUMBER, "translation along x", unit="m", minimum=-2.0, maximum=2.0),
        ParamSpec("dy", ParamType.NUMBER, "translation along y", unit="m", minimum=-2.0, maximum=2.0),
        ParamSpec("dz", ParamType.NUMBER, "translation along z", unit="m", minimum=-2.0, maximum=2.0),
        ParamSpec("droll", ParamType.NUMBER, "rotation about x", unit="rad", default="0", minimum=-6.3, maximum=6.3),
        ParamSpec("dpitch", ParamType.NUMBER, "rotation about y", unit="rad", default="0", minimum=-6.3, maximum=6.3),
        ParamSpec("dyaw", ParamType.NUMBER, "rotation about z", unit="rad", default="0", minimum=-6.3, maximum=6.3),
        ParamSpec("reference", ParamType.CHOICE, "world: axes of the world frame; tool: axes of the current TCP frame", default="world", choices=("world", "tool")),
        states=("Motion",),
    )
    def move_relative(
        self, dx: float, dy: float, dz: float, droll: float = 0.0, dpitch: float = 0.0, dyaw: float = 0.0, reference: str = "world"
    ) -> Skill:
        """Linear TCP move by an offset, in world or tool axes (like V+ move_rel_world / move_rel_tool)."""
        yield MoveRelative(Pose.from_xyz_rpy(dx, dy, dz, droll, dpitch, dyaw), reference, "linear")  # type: ignore[arg-type]

    @skill(
        ParamSpec("fraction", ParamType.NUMBER, "fraction of the robot's maximum speed for the following motions (0.5 or 50%)", unit="fraction", minimum=0.01, maximum=1.0),
        groups=ANY_GROUP,
        states=("Motion",),
    )
    def set_speed(self, fraction: float) -> Skill:
        """Set the speed of this group's following motions."""
        yield SetSpeed(fraction)

    @skill(
        ParamSpec("seconds", ParamType.NUMBER, "0: sit this operation out; more: hold position that long", unit="s", default="0", minimum=0.0, maximum=3600.0),
        groups=ANY_GROUP,
        states=("Motion",),
    )
    def wait(self, seconds: float = 0.0) -> Skill:
        """Synchronisation: the group does nothing in this operation (or holds still for some seconds)."""
        if seconds > 0:
            yield Dwell(seconds)

    # ------------------------------------------------------------------------ flags
    @skill(ParamSpec("name", ParamType.NAME, "the flag: groups waiting for it go on"), groups=ANY_GROUP)
    def set_flag(self, name: str) -> Skill:
        """Synchronisation (paper §2.2.3, "flags"): say that this group got here; every group waiting
        for the flag goes on.  A flag stays set until the application ends.  The execution engine
        carries it out (it takes no time and moves nothing)."""
        raise RuntimeError(f"set_flag({name}) is carried out by the execution engine, not by a group machine")
        yield  # pragma: no cover - a generator, like every skill

    @skill(
        ParamSpec("name", ParamType.NAME, "the flag to wait for"),
        ParamSpec("timeout", ParamType.NUMBER, "longest wait before the function fails (fault: timeout)", unit="s", default="600", minimum=0.001, maximum=86400.0),
        groups=ANY_GROUP,
    )
    def wait_flag(self, name: str, timeout: float = 600.0) -> Skill:
        """Synchronisation: hold still until another group sets the flag (at once if it is set
        already).  ``validate`` refuses a wait no other group's set_flag can end, and circular
        waits.  The execution engine carries it out."""
        raise RuntimeError(f"wait_flag({name}) is carried out by the execution engine, not by a group machine")
        yield  # pragma: no cover - a generator, like every skill

    # ------------------------------------------------------------------------ end effector
    @skill(states=("EndEffector",), leaves=Hold.NOTHING)
    def gripper_open(self) -> Skill:
        """Open the group's gripper (releases whatever it held)."""
        yield EndEffector("gripper_open")

    @skill(states=("EndEffector",), leaves=Hold.UNKNOWN)
    def gripper_close(self) -> Skill:
        """Close the group's gripper."""
        yield EndEffector("gripper_close")

    @skill(
        ParamSpec("action", ParamType.CHOICE, "the tool or hand action", choices=END_EFFECTOR_ACTIONS),
        states=("EndEffector",),
        leaves=Hold.UNKNOWN,
    )
    def end_effector(self, action: str) -> Skill:
        """Any end-effector action: gripper, air, deburring tool on/off, Nextage air hand draw-in/keep/release."""
        yield EndEffector(action)  # type: ignore[arg-type]

    @skill(
        ParamSpec("target", ParamType.TARGET, "where the part is: the TCP pose that grasps it (frame or x,y,z,roll,pitch,yaw)", unit="m, rad"),
        _REACH_DISTANCE,
        states=("Motion", "EndEffector"),
        requires=Hold.NOTHING,
        leaves=Hold.PART,
    )
    def pick(self, target: str | Pose, distance: float = 0.05) -> Skill:
        """Pick a part: open the gripper, approach along the target's z, go straight in, close, retreat straight out."""
        yield EndEffector("gripper_open")
        yield from self.reach_in(target, distance, "grasp", "gripper_close")

    @skill(
        ParamSpec("target", ParamType.TARGET, "where the part goes: the TCP pose that releases it (frame or x,y,z,roll,pitch,yaw)", unit="m, rad"),
        _REACH_DISTANCE,
        states=("Motion", "EndEffector"),
        requires=Hold.PART,
        leaves=Hold.NOTHING,
    )
    def place(self, target: str | Pose, distance: float = 0.05) -> Skill:
        """Place the held part: approach along the target's z, go straight in, open the gripper, retreat straight out."""
        yield from self.reach_in(target, distance, "release", "gripper_open")

    # ------------------------------------------------------------------------------ signals
    @skill(
        ParamSpec("name", ParamType.NAME, "the signal as the controller's configuration names it (KUKA RSI: GPIO.01, Tech.T21)"),
        _SIGNAL_VALUE,
        states=("EndEffector",),
    )
    def set_output(self, name: str, value: float) -> Skill:
        """Set a signal the controller receives (a digital or numeric output of its RSI configuration); done once it has left."""
        yield SetOutput(name, value)

    @skill(
        ParamSpec("name", ParamType.NAME, "the signal as the controller's configuration names it (KUKA RSI: GPIO.02, Tech.C11)"),
        _SIGNAL_VALUE,
        ParamSpec("timeout", ParamType.NUMBER, "longest wait before the function fails (fault: timeout)", unit="s", default="10", minimum=0.0, maximum=86400.0),
        ParamSpec("tolerance", ParamType.NUMBER, "how far a numeric signal may lie from the value", unit="", default="0", minimum=0.0, maximum=1e9),
        states=("EndEffector",),
    )
    def wait_input(self, name: str, value: float, timeout: float = 10.0, tolerance: float = 0.0) -> Skill:
        """Hold still until a signal the controller sends reads the value (a sensor, a PLC's go), or fail after the timeout."""
        yield WaitInput(name, value, timeout, tolerance)

    # ----------------------------------------------------------------------------- vision
    @skill(
        ParamSpec("target", ParamType.FRAME, "the cell frame to find"),
        ParamSpec("camera", ParamType.CAMERA, "a camera of the robot, or auto for the group's own camera", default="auto"),
        groups=ANY_GROUP,
        states=("Vision",),
        outcomes=VISION_OUTCOMES,
    )
    def locate(self, target: str, camera: str = "auto") -> Skill:
        """Find a frame with a camera; this group's later moves to it, and to every frame below it in the cell, use the measured pose."""
        yield from self.locate_frame(target, "" if camera == "auto" else camera)

    @skill(
        ParamSpec("target", ParamType.FRAME, "the round feature to measure (a hole: a frame with a diameter in the cell)"),
        ParamSpec("minimum", ParamType.NUMBER, "the smallest diameter accepted", unit="m", minimum=1e-5, maximum=1.0),
        ParamSpec("maximum", ParamType.NUMBER, "the largest diameter accepted", unit="m", minimum=1e-5, maximum=1.0),
        ParamSpec("camera", ParamType.CAMERA, "a camera of the robot, or auto for the group's own camera", default="auto"),
        groups=ANY_GROUP,
        states=("Vision",),
        outcomes=MEASURE_OUTCOMES,
    )
    def check_diameter(self, target: str, minimum: float, maximum: float, camera: str = "auto") -> Skill:
        """Find a round feature with a camera and check its measured diameter against a range; later moves to it use the measured pose."""
        if minimum > maximum:
            raise ValueError(f"minimum {minimum * 1000:g} mm is above maximum {maximum * 1000:g} mm")
        result: VisionResult = yield Vision("locate", target=target, nominal=self.cell.nominal(target), camera=self.camera() if camera == "auto" else camera)
        if result.pose is None:
            raise LookupError(f"vision found no pose for {target!r}")
        self.cell.correct(target, result.pose)
        diameter = result.report.diameter if result.report is not None else 0.0
        if not diameter > 0.0:
            raise LookupError(f"the camera measured no diameter of {target!r} (a camera that only locates: it cannot check a size)")
        self.ctx.measurements[f"{target}.diameter"] = diameter
        if not minimum <= diameter <= maximum:
            raise OutOfRange(f"{target}: diameter {diameter * 1000:.3f} mm, outside {minimum * 1000:g} to {maximum * 1000:g} mm")

    # ------------------------------------------------------------------------ trajectories
    @skill(
        ParamSpec("name", ParamType.NAME, "the name to store the trajectory under"),
        ParamSpec("waypoints", ParamType.FRAMES, "cell frames to pass through, in order"),
        _INTERPOLATION,
        _OVERWRITE,
        states=("RecordTrajectory",),
    )
    def record_trajectory(self, name: str, waypoints: tuple[str, ...], interpolation: str = "ptp", overwrite: bool = False) -> Skill:
        """Plan a trajectory through cell frames (without moving) and store it in the trajectory database."""
        self.ctx.trajectories.check_overwrite(self.ctx.group, name, overwrite)
        poses = tuple(self.resolve(w) for w in waypoints)
        result: TrajectoryResult = yield RecordTrajectory(name, "plan", poses, interpolation)  # type: ignore[arg-type]
        self.ctx.trajectories.save(self.ctx.group, name, result, "plan", self.ctx.now(), overwrite)

    @skill(
        ParamSpec("name", ParamType.NAME, "the name to store the trajectory under"),
        ParamSpec("duration", ParamType.NUMBER, "how long to record", unit="s", minimum=0.1, maximum=600.0),
        ParamSpec("sample_period", ParamType.NUMBER, "time between samples", unit="s", default="0.1", minimum=0.004, maximum=10.0),
        _OVERWRITE,
        groups=ANY_GROUP,
        states=("RecordTrajectory",),
    )
    def teach_trajectory(self, name: str, duration: float, sample_period: float = 0.1, overwrite: bool = False) -> Skill:
        """Teach by demonstration: sample the group's joints while it is guided, and store the trajectory."""
        self.ctx.trajectories.check_overwrite(self.ctx.group, name, overwrite)
        result: TrajectoryResult = yield RecordTrajectory(name, "teach", duration=duration, sample_period=sample_period)
        self.ctx.trajectories.save(self.ctx.group, name, result, "teach", self.ctx.now(), overwrite)

    @skill(
        ParamSpec("name", ParamType.NAME, "a trajectory recorded earlier for this group"),
        groups=ANY_GROUP,
        states=("TrajectoryExecution",),
    )
    def execute_trajectory(self, name: str) -> Skill:
        """Replay a stored trajectory (timing scaled by the set speed)."""
        stored = self.ctx.trajectories.load(self.ctx.group, name).trajectory
        yield ExecuteTrajectory(name, stored.joint_names, stored.points, stored.times)

    # ---------------------------------------------------------------------- coordination
    @skill(
        ParamSpec("pose", ParamType.JOINT_POSE, "a whole-robot named joint pose (robot pose or a cell <joint_pose> without group)", kinds=("robot",)),
        groups=ANY_GROUP,
        states=("FullBodyMotion",),
        sync="full_body",
    )
    def full_body_move(self, pose: str) -> Skill:
        """Coordinated move of every joint of the robot; give it to both arms (and torso_head) in one operation."""
        names, values = self.whole_robot_pose(pose)
        yield FullBodyMove(names, values)

    @skill(
        ParamSpec("target", ParamType.TARGET, "where the master's TCP goes (frame or x,y,z,roll,pitch,yaw)", unit="m, rad"),
        ParamSpec("slave", ParamType.GROUP, "the arm that follows with a fixed offset (it calls slave_follow)"),
        states=("MasterSlave",),
        sync="master_slave",
    )
    def master_move(self, target: str | Pose, slave: str) -> Skill:
        """Bi-manual move: this arm leads in a straight line; the slave keeps its current offset to it."""
        yield MasterSlaveMove(master=self.ctx.group, slave=slave, master_path=(self.resolve(target),), offset=None)

    @skill(
        ParamSpec("master", ParamType.GROUP, "the arm that leads (it calls master_move)"),
        states=("MasterSlave",),
        sync="master_slave",
    )
    def slave_follow(self, master: str) -> Skill:
        """Follow the master arm's master_move in the same operation, keeping the current offset."""
        yield MasterSlaveMove(master=master, slave=self.ctx.group, master_path=(), offset=None)
