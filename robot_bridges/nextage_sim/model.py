"""Nextage Open kinematics on pinocchio: forward kinematics of any frame, per-arm inverse kinematics.

The simulator needs two things from a kinematic model: where every frame is for a joint vector
(joint states, TCP poses, camera positions), and which arm joints put a TCP at a Cartesian target
(every Cartesian primitive).  Both come from the project's own URDF, loaded with pinocchio, so the
numbers are the ones a ROS user sees in RViz and ``tf``.

Conventions: the world frame is ``WAIST`` (the robot base); joint vectors ("q") hold the 15 joints
in pinocchio's order (:attr:`NextageModel.joint_names`); an arm's TCP is the origin of
``*ARM_JOINT5_Link`` composed with a configurable tool offset.  Arm IK holds the torso
(``CHEST_JOINT0``) where it is: it solves on a 6-joint pinocchio model of the arm alone, which is
what a dual-arm controller does (the torso is its own group) and cheaper than the whole robot.
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from core_functions.geometry import Pose
from core_functions.robots import NEXTAGE_OPEN
from robot_bridges.backend import BridgeError, FaultKind

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

URDF_PATH = Path(__file__).resolve().parent / "urdf" / "nextage_open.urdf"
WORLD_FRAME = "WAIST"
TORSO_JOINT = "CHEST_JOINT0"
TORSO_LINK = "CHEST_JOINT0_Link"
ARM_PREFIXES: dict[str, str] = {"left_arm": "LARM", "right_arm": "RARM"}
#: Joint acceleration limit (rad/s^2) of every joint: the arms' MoveIt joint_limits value.
ACCELERATION_LIMIT = 1.5


def flange_frame(group: str) -> str:
    """The link whose origin is the arm's TCP without a tool (``LARM_JOINT5_Link``)."""
    return f"{ARM_PREFIXES[group]}_JOINT5_Link"


def describe_target(target: Pose) -> str:
    """Position in m and rpy in degrees: how error messages name a Cartesian target."""
    roll, pitch, yaw = (math.degrees(a) for a in target.rpy())
    return (
        f"({target.x:.4f}, {target.y:.4f}, {target.z:.4f}) m, "
        f"rpy ({roll:.1f}, {pitch:.1f}, {yaw:.1f}) deg"
    )


@dataclass(frozen=True)
class IKOptions:
    """Tolerances and effort bounds of the arm IK.

    The tolerances are well below what a kinematic simulation needs (0.01 mm, 0.006 deg) so that
    round trips in tests measure the solver, not the tolerance.  Restarts are deterministic: the
    same target and seed always give the same answer.
    """

    position_tolerance: float = 1e-5  # m
    orientation_tolerance: float = 1e-4  # rad
    max_iterations: int = 60
    restarts: int = 24  # 12 missed an in-limits branch hypothesis found (test_ik_round_trip_from_the_initial_pose's example)
    max_step: float = 0.5  # rad per iteration, keeps DLS steps inside the linear region
    damping: float = 1e-6  # bias of the squared DLS damping (which also grows with the error)
    restart_seed: int = 20170419
    rotation_weight: float = 0.1  # m per rad: how the error trades orientation against position


@dataclass(frozen=True)
class IKSolution:
    """Arm joint values (group order) and how far their TCP is from the target."""

    positions: Vector
    position_error: float  # m
    orientation_error: float  # rad
    attempts: int


class ArmKinematics:
    """One 6-joint arm with the torso held: TCP forward kinematics and inverse kinematics.

    Solving happens on a pinocchio model reduced to the arm's joints with the torso locked at 0;
    the torso's actual angle enters as a fixed world transform, so a rotated torso costs nothing.
    """

    def __init__(self, full: NextageModel, group: str, options: IKOptions, tool: Pose | None = None) -> None:
        self.group = group
        self.options = options
        self.joint_names = tuple(f"{ARM_PREFIXES[group]}_JOINT{i}" for i in range(6))
        self.indices = np.array([full.index(n) for n in self.joint_names])
        self._full = full
        locked = [full.model.getJointId(n) for n in full.joint_names if n not in self.joint_names]
        self.model = pin.buildReducedModel(full.model, locked, pin.neutral(full.model))
        self.data = self.model.createData()
        self.frame_id = self.model.getFrameId(flange_frame(group))
        arm_ids = [self.model.idx_qs[self.model.getJointId(n)] for n in self.joint_names]
        if arm_ids != list(range(6)):
            raise RuntimeError(f"{group}: reduced arm model has unexpected joint order {arm_ids}")
        self.lower = full.lower[self.indices].copy()
        self.upper = full.upper[self.indices].copy()
        self._unbounded_lower = np.full(6, -np.inf)
        self._unbounded_upper = np.full(6, np.inf)
        self._chest_zero_inv = _rigid_inverse(full.frame_matrix(full.neutral(), TORSO_LINK))
        self._initial = full.named_pose("initial")[self.indices]
        rng = np.random.default_rng(options.restart_seed + (0 if group == "left_arm" else 1))
        margin = 0.05 * (self.upper - self.lower)
        self._restart_seeds = [self._initial] + [
            rng.uniform(self.lower + margin, self.upper - margin) for _ in range(max(0, options.restarts - 1))
        ]
        self.tool = tool or Pose()
        self._eye6 = np.eye(6)

    # ---------------------------------------------------------------------------- tool
    @property
    def tool(self) -> Pose:
        return self._tool

    @tool.setter
    def tool(self, tool: Pose) -> None:
        self._tool = tool
        self._tool_m = tool.matrix()
        self._tool_inv = _rigid_inverse(self._tool_m)

    # ------------------------------------------------------------------------------ FK
    def base_matrix(self, q_full: Vector) -> Matrix:
        """World pose of the reduced arm model's origin for the torso angle in ``q_full``."""
        return self._full.frame_matrix(q_full, TORSO_LINK) @ self._chest_zero_inv

    def tcp_matrix(self, q_full: Vector) -> Matrix:
        return self._full.frame_matrix(q_full, flange_frame(self.group)) @ self._tool_m

    def tcp_pose(self, q_full: Vector) -> Pose:
        return Pose.from_matrix(self.tcp_matrix(q_full))

    # ------------------------------------------------------------------------------ IK
    def solve(self, target: Pose, q_full: Vector, *, restarts: bool = True) -> IKSolution:
        """Arm joints putting the TCP at ``target`` (world frame), torso as in ``q_full``.

        The search starts at the arm's joints in ``q_full`` (so nearby targets give nearby
        solutions) and, if that fails and ``restarts`` is set, from a bounded list of fixed
        seeds.  Raises ``BridgeError(UNREACHABLE)`` naming the arm, the target and the best
        residual when no attempt converges inside the joint limits.
        """
        goal = _rigid_inverse(self.base_matrix(q_full)) @ target.matrix() @ self._tool_inv
        goal_r = np.ascontiguousarray(goal[:3, :3])
        goal_p = np.ascontiguousarray(goal[:3, 3])
        warm = np.clip(q_full[self.indices], self.lower, self.upper)
        best: tuple[float, float, float] | None = None
        beyond_limits: Vector | None = None  # a solution that exists, but only outside the limits
        attempt = 0
        for seed, bounded in self._seeds(warm, restarts):
            attempt += 1
            q, pos_err, rot_err, ok = self._descend(goal_r, goal_p, seed.copy(), bounded)
            if ok and not bounded:
                wrapped = self._wrap_into_limits(q, seed)
                if wrapped is None and beyond_limits is None:
                    beyond_limits = q
                ok, q = wrapped is not None, q if wrapped is None else wrapped
            if ok:
                return IKSolution(q, pos_err, rot_err, attempt)
            score = pos_err + 0.1 * rot_err
            if best is None or score < best[0]:
                best = (score, pos_err, rot_err)
        assert best is not None
        if beyond_limits is not None:
            raise BridgeError(FaultKind.JOINT_LIMIT, self._beyond_limits_message(target, beyond_limits))
        raise BridgeError(
            FaultKind.UNREACHABLE,
            f"{self.group}: no IK solution for TCP target {describe_target(target)}; best residual "
            f"{best[1] * 1000:.1f} mm / {math.degrees(best[2]):.2f} deg after {attempt} attempt(s)",
        )

    def _beyond_limits_message(self, target: Pose, q: Vector) -> str:
        """Name the joint that keeps a geometrically reachable target out of reach."""
        overshoot = np.maximum(self.lower - q, q - self.upper)
        worst = int(np.argmax(overshoot))
        name = self.joint_names[worst]
        return (
            f"{self.group}: TCP target {describe_target(target)} is reachable only with {name} = "
            f"{math.degrees(q[worst]):.1f} deg, outside its limits [{math.degrees(self.lower[worst]):.1f}, "
            f"{math.degrees(self.upper[worst]):.1f}] deg (try the target rotated about its z axis)"
        )

    def _seeds(self, warm: Vector, restarts: bool) -> Iterator[tuple[Vector, bool]]:
        """(seed, bounded) pairs: the warm start inside the limits; then, only if needed and
        allowed, each of the warm start and the fixed restart seeds free of limits (the answer
        wrapped back by whole turns, which often lands inside: wrist rolls) and inside them."""
        yield warm, True
        if restarts:
            yield warm, False
            for seed in self._restart_seeds:
                if float(np.max(np.abs(seed - warm))) > 1e-9:
                    yield seed, False
                    yield seed, True

    def _wrap_into_limits(self, q: Vector, seed: Vector) -> Vector | None:
        """``q`` with joints moved by whole turns into their limits (the same pose), or None.

        Among the turns that fit, each joint takes the one closest to the seed.
        """
        turn = 2.0 * math.pi
        wrapped = q.copy()
        for i in range(len(q)):
            fits = [q[i] + k * turn for k in range(-2, 3) if self.lower[i] - 1e-12 <= q[i] + k * turn <= self.upper[i] + 1e-12]
            if not fits:
                return None
            wrapped[i] = min(fits, key=lambda v: abs(v - seed[i]))
        return wrapped

    def _descend(self, goal_r: Matrix, goal_p: Vector, q: Vector, bounded: bool = True) -> tuple[Vector, float, float, bool]:
        """Levenberg-Marquardt (damped least squares) with a joint-limit-aware step, from one seed.

        A step is kept only if it lowers the error, otherwise the damping grows and the step
        shrinks towards the gradient; joints sitting on a limit whose step would push them
        further out are taken out of the Jacobian, so the other joints do the work.  Every
        iterate is inside the limits, and so is the answer (never clipped afterwards into a
        different pose).  Stops early when progress stalls (a local minimum on the limits).
        With ``bounded`` false the limits are ignored; the caller wraps the answer back.
        """
        opts = self.options
        lower, upper = (self.lower, self.upper) if bounded else (self._unbounded_lower, self._unbounded_upper)
        w = opts.rotation_weight
        e = self._error(goal_r, goal_p, q)
        cost = float(e @ e)
        boost = 1.0
        stalled = 0
        for _ in range(opts.max_iterations):
            pos_err, rot_err = _norms(e)
            if pos_err < opts.position_tolerance and rot_err < opts.orientation_tolerance * w:
                return q, pos_err, rot_err / w, True
            jac = pin.computeFrameJacobian(self.model, self.data, q, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
            if w != 1.0:
                jac = jac.copy()
                jac[3:] *= w
            descent = jac.T @ e
            blocked = ((q <= lower + 1e-9) & (descent < 0)) | ((q >= upper - 1e-9) & (descent > 0))
            if blocked.any():
                jac = jac.copy()
                jac[:, blocked] = 0.0
            jjt = jac @ jac.T
            for _ in range(8):  # bounded damping increases before giving up this iterate
                damping = boost * (0.5 * cost + opts.damping)
                dq = jac.T @ np.linalg.solve(jjt + damping * self._eye6, e)
                largest = float(np.max(np.abs(dq)))
                if largest > opts.max_step:
                    dq *= opts.max_step / largest
                trial = np.clip(q + dq, lower, upper)
                e_trial = self._error(goal_r, goal_p, trial)
                trial_cost = float(e_trial @ e_trial)
                if trial_cost < cost:
                    stalled = stalled + 1 if trial_cost > 0.9999 * cost else 0
                    q, e, cost = trial, e_trial, trial_cost
                    boost = max(1.0, boost * 0.3)
                    break
                boost *= 10.0
            else:
                break
            if stalled >= 10:
                break
        pos_err, rot_err = _norms(e)
        ok = pos_err < opts.position_tolerance and rot_err < opts.orientation_tolerance * w
        return q, pos_err, rot_err / w, ok

    def _error(self, goal_r: Matrix, goal_p: Vector, q: Vector) -> Vector:
        """Position error and rotation vector of goal w.r.t. the flange, both in world axes."""
        pin.forwardKinematics(self.model, self.data, q)
        placement = pin.updateFramePlacement(self.model, self.data, self.frame_id)
        e = np.empty(6)
        e[:3] = goal_p - placement.translation
        e[3:] = pin.log3(goal_r @ placement.rotation.T) * self.options.rotation_weight
        return e


def _norms(e: Vector) -> tuple[float, float]:
    """Lengths of the position and rotation halves of a 6-vector (cheaper than np.linalg.norm)."""
    x, y, z, a, b, c = e.tolist()
    return math.sqrt(x * x + y * y + z * z), math.sqrt(a * a + b * b + c * c)


def _rigid_inverse(m: Matrix) -> Matrix:
    inverse = np.eye(4)
    inverse[:3, :3] = m[:3, :3].T
    inverse[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return inverse


class NextageModel:
    """The whole robot (15 joints) loaded from the project's URDF."""

    def __init__(self, urdf_path: Path | str = URDF_PATH, ik_options: IKOptions | None = None) -> None:
        self.urdf_path = Path(urdf_path)
        self.model = pin.buildModelFromUrdf(str(self.urdf_path))
        self.data = self.model.createData()
        names = [self.model.names[i] for i in range(1, self.model.njoints)]
        if self.model.nq != len(names):
            raise ValueError(f"{self.urdf_path}: only single-DOF revolute joints are supported")
        self.joint_names: tuple[str, ...] = tuple(names)
        self._index = {n: self.model.idx_qs[self.model.getJointId(n)] for n in names}
        self.lower: Vector = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper: Vector = np.array(self.model.upperPositionLimit, dtype=float)
        self.velocity: Vector = np.array(self.model.velocityLimit, dtype=float)
        self.acceleration: Vector = np.full(self.model.nq, ACCELERATION_LIMIT)
        self._frame_ids: dict[str, int] = {}
        options = ik_options or IKOptions()
        self.arms = {g: ArmKinematics(self, g, options) for g in ARM_PREFIXES}

    # ----------------------------------------------------------------------------- joints
    def index(self, joint: str) -> int:
        try:
            return self._index[joint]
        except KeyError:
            raise KeyError(f"the Nextage model has no joint {joint!r}") from None

    def indices(self, joints: tuple[str, ...] | list[str]) -> NDArray[np.int64]:
        return np.array([self.index(n) for n in joints], dtype=np.int64)

    def neutral(self) -> Vector:
        return np.zeros(self.model.nq)

    def named_pose(self, name: str) -> Vector:
        """A named whole-robot pose of :data:`NEXTAGE_OPEN` ("initial", "off") as a joint vector."""
        try:
            values = NEXTAGE_OPEN.poses[name]
        except KeyError:
            raise KeyError(f"unknown Nextage pose {name!r} (known: {', '.join(sorted(NEXTAGE_OPEN.poses))})") from None
        q = self.neutral()
        for joint, value in values.items():
            q[self.index(joint)] = value
        return q

    def limit_violation(self, q: Vector, indices: NDArray[np.int64] | None = None, tolerance: float = 1e-9) -> str | None:
        """A message naming the first joint of ``q`` outside its limits, or None."""
        idx = np.arange(self.model.nq) if indices is None else indices
        for i in idx:
            value = float(q[i])
            if not (self.lower[i] - tolerance <= value <= self.upper[i] + tolerance):
                name = self.joint_names[i]
                return (
                    f"{name} = {value:.4f} rad ({math.degrees(value):.2f} deg) is outside its limits "
                    f"[{math.degrees(self.lower[i]):.1f}, {math.degrees(self.upper[i]):.1f}] deg"
                )
        return None

    # -------------------------------------------------------------------------------- FK
    def frame_id(self, frame: str) -> int:
        fid = self._frame_ids.get(frame)
        if fid is None:
            if not self.model.existFrame(frame):
                raise KeyError(f"the Nextage model has no frame {frame!r}")
            fid = self._frame_ids[frame] = self.model.getFrameId(frame)
        return fid

    def frame_matrix(self, q: Vector, frame: str) -> Matrix:
        """4x4 pose of ``frame`` in ``WAIST`` for the joint vector ``q``."""
        fid = self.frame_id(frame)
        pin.forwardKinematics(self.model, self.data, q)
        return np.array(pin.updateFramePlacement(self.model, self.data, fid).homogeneous)

    def frame_pose(self, q: Vector, frame: str) -> Pose:
        return Pose.from_matrix(self.frame_matrix(q, frame))
