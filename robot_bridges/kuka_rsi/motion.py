"""Where one robot's set point goes, planned from what the external system itself commanded.

:class:`Motion` owns the generators (joint and Cartesian), the streamed tool path, the
corrections and the model of what the controller holds of them (:mod:`.setpoint`).  Every plan
starts from that commanded set point -- a move, a catch-up after late replies, a stream's
re-entry, a change of space -- never from ``ASPos``/``RSol``: what the controller *reports* is only
checked against it (:meth:`Motion.cross_check`), because a peer can report anything (ROS-I's
simulator keeps reporting its start pose, and a catch-up "from where the robot is" then commanded
a jump back to it).  The one report taken as an input is the set point when RSI_MOVECORR begins:
corrections are measured from there.

Each cycle, after the generator or the stream has proposed the next correction, the limiter
(:mod:`.guard`) holds the step to the axes' speed and acceleration, measured from the set point
the controller holds; a clamped step is reported and the generator goes on from what was sent.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from robot_bridges.kuka_rsi.convention import ReportCheck
from robot_bridges.kuka_rsi.guard import AXES, limit_joint_step, limit_vector_step
from robot_bridges.kuka_rsi.kinematics import KukaArm, abc_to_matrix, matrix_to_abc, rotation_angle
from robot_bridges.kuka_rsi.link import RobotLink
from robot_bridges.kuka_rsi.otg import CartesianOTG, VectorOTG, matrix_to_rotvec, rotvec_to_matrix
from robot_bridges.kuka_rsi.setpoint import CorrectionModel, cartesian_increment, compose_cartesian
from robot_bridges.kuka_rsi.streaming import STILL, StreamCursor, ToolPath, ramp_rate

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]
_DEG = math.pi / 180.0
#: Cycles without a reply played forward at most per packet (RSI stops long before: Timeout).
MAX_HELD_CYCLES = 1000
#: Decimals of a DOUBLE in a packet (the codec's "%.6f").
PACKET_DECIMALS = 6
#: The Cartesian correction's tags, for messages.
_RK_NAMES = ("X", "Y", "Z", "A", "B", "C")


def _pose(p: Vector, r: Matrix) -> Matrix:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, p
    return m


class Motion:
    """The set point of one robot: generators, stream, corrections, and the controller's share of them."""

    def __init__(
        self,
        link: RobotLink,
        holdon_ak: tuple[bool, ...],
        holdon_rk: tuple[bool, ...],
        reported: Callable[[bool], Matrix | None],
        warn: Callable[[str, str], None],
        check: ReportCheck,
    ) -> None:
        """``reported(actual)`` reads the controller's TCP of the current packet (4x4): RSol, or with
        ``actual`` RIst; None when the configuration does not send it.  Taken only as the offset between
        its kinematic model and ours.  ``warn(key, text)`` reports a clamp; ``check`` is the cross-check."""
        self.link = link
        dt = self.dt = link.cycle_ms / 1000.0
        self.relative = link.correction_mode == "relative"
        self.arm = KukaArm()
        self.vmax = np.array(link.max_joint_speed)
        self.amax = np.array(link.max_joint_accel)
        self._max_step, self._max_change = self.vmax * dt, self.amax * dt * dt
        self._linear = (link.max_linear_speed * dt, link.max_linear_accel * dt * dt)
        self._angular = (link.max_angular_speed * dt, link.max_angular_accel * dt * dt)
        self.tolerance = np.radians(np.array(link.setpoint_tolerance_deg))
        self._reported = reported
        self._warn = warn
        self.check = check
        depth = link.report_lag_cycles + 2
        self._depth = depth
        # The commanded set points of the last follow_time: the path an actual position must lie on.
        self._span = max(depth, math.ceil(link.follow_time / dt - 1e-9) + 1)
        self.ak_model = CorrectionModel(holdon_ak, self.relative, depth)
        self.rk_model = CorrectionModel(holdon_rk, self.relative, depth, compose_cartesian)
        self._keeps_moving = (self.relative and all(holdon_ak), self.relative and all(holdon_rk))
        self.joint = VectorOTG([1] * 6, dt)
        self.cart = CartesianOTG(dt)
        self.mode = "joint"  # which drives the corrections: joint, cart, stream
        self.stream_space = "joint"
        self.cursor: StreamCursor | None = None
        self.override = 1.0  # the operator's speed override (set_override)
        self.path: ToolPath | None = None
        self.q_ref = np.zeros(6)
        self.base = np.eye(4)  # the pose (our kinematics) the Cartesian correction is measured from
        self.calibration = np.eye(4)  # the controller's RSol = calibration @ our pose
        self.actual_calibration = np.eye(4)  # the controller's RIst = actual_calibration @ our pose
        self.ak = np.zeros(6)  # deg: the absolute axis correction we want in force
        self.rk = np.zeros(6)  # mm / deg: the absolute Cartesian correction we want in force
        self.track: deque[Vector] = deque([np.zeros(6)] * depth, maxlen=depth)  # held set points, newest last
        self.window: deque[Vector] = deque([np.zeros(6)], maxlen=self._span)  # the same, over follow_time
        self._fold_point = np.zeros(6)
        self._reply: tuple[Vector | None, Vector | None, tuple[float, float] | None] = (None, None, None)
        self._applied_cursor = (0.0, 0.0)
        self.commanded = np.zeros(6)  # rad: the joint set point we command (for the application)
        self._cart_joints: Vector | None = None
        self.moved = False
        self.quiet = 0
        self.clamped = 0
        self.clamps: dict[str, int] = {}

    # ------------------------------------------------------------------ the commanded set point
    def begin(self, q: Vector, in_force: Vector | None = None) -> None:
        """RSI_MOVECORR began with the controller's set point at ``q``: corrections count from here.

        ``in_force`` (deg): an axis correction the controller still applies from before -- ROS-I's
        simulator keeps its absolute correction between connections, its ASPos at the start and its
        robot where the last one left it.  It is taken as the correction in force, so the first reply
        holds the robot where it stands instead of sending it back to ``q``."""
        self.q_ref = q.copy()
        self.ak_model.reset()
        self.rk_model.reset()
        self.ak, self.rk = np.zeros(6), np.zeros(6)
        if in_force is not None:
            self.ak_model.start_from(in_force)
            self.ak = in_force.copy()
        here = q + self.ak * _DEG
        self.mode, self.cursor = "joint", None
        self.joint.reset(here)
        self._fold_point = here.copy()
        self.track = deque([here.copy()] * self._depth, maxlen=self._depth)
        self.window = deque([here.copy()], maxlen=self._span)
        self.commanded = here.copy()
        self._reply = (None, None, None)
        self.moved, self.quiet = True, 0

    def begin_from(self, setpoint: Vector, actual: Vector, axis_corrections: bool) -> str | None:
        """:meth:`begin` at the reported set point; when the axes stand beyond the tolerance from it (and
        axis corrections are configured), with the correction that holds them where they stand -- the
        controller still applies one from before -- and what to report of it."""
        apart = np.abs(actual - setpoint)
        if not axis_corrections or not (apart > self.check.tolerance).any():
            self.begin(setpoint)
            return None
        self.begin(setpoint, (actual - setpoint) / _DEG)  # sending none would send the robot back to the set point in one cycle
        i = int(np.argmax(apart))
        return (
            f"as RSI_MOVECORR begins A{i + 1} stands {math.degrees(float(actual[i] - setpoint[i])):.3f} deg from the reported set point (ASPos): "
            "the controller keeps a correction from before (as ROS-Industrial's kuka_rsi_simulator does between connections); "
            "corrections go on from it, holding the robot where it stands"
        )

    def space(self) -> str:
        """The space the corrections move in: joint or cart."""
        return self.stream_space if self.mode == "stream" else self.mode

    def held(self) -> Vector:
        """The set point the controller holds as far as our replies say: joints (rad) or a 4x4 pose."""
        return self.track[-1]

    def _held_now(self) -> Vector:
        if self.space() == "joint":
            # Until the controller has the fold's packet the Cartesian correction is still in force,
            # but both put it on the same set point: the fold happens at rest.
            rk = self.rk_model.total
            folded = not rk.any() or float(np.max(np.abs(rk))) < 1e-9
            return self.q_ref + self.ak_model.total * _DEG if folded else self._fold_point.copy()
        rk = self.rk_model.total
        return _pose(self.base[:3, 3] + rk[:3] / 1000.0, abc_to_matrix(*(rk[3:] * _DEG)) @ self.base[:3, :3])

    def settle(self, applied: bool, held: int) -> bool:
        """Play the controller's cycles since our last reply: that one (if ``applied``), then ``held``
        cycles without a reply.  After a held cycle the running motion goes on from the set point
        the controller holds.  True when some cycle held."""
        if applied:
            self._cycle(*self._reply)
        for _ in range(min(held, MAX_HELD_CYCLES)):
            self._cycle(None, None, None)
        if held:
            self._catch_up()
        return held > 0

    def _cycle(self, ak: Vector | None, rk: Vector | None, cursor: tuple[float, float] | None) -> None:
        self.ak_model.cycle(ak)
        self.rk_model.cycle(rk)
        if cursor is not None:
            self._applied_cursor = cursor
        elif ak is None and rk is None:
            position, rate = self._applied_cursor
            keeps = self._keeps_moving[0 if self.stream_space == "joint" else 1]
            self._applied_cursor = (position + rate, rate) if keeps else (position, 0.0)
        held = self._held_now()
        self.track.append(held)
        self.window.append(held)

    def _catch_up(self) -> None:
        """Go on from where the controller holds the set point, at the speed it holds it with."""
        held, before = self.track[-1], self.track[-2]
        if self.mode == "stream" and self.cursor is not None:
            self.cursor.hold(*self._applied_cursor)
        elif self.mode == "joint":
            self.joint.resync(held, (held - before) / self.dt)
            self.ak, self.rk = (held - self.q_ref) / _DEG, np.zeros(6)
        else:
            velocity = np.concatenate(((held[:3, 3] - before[:3, 3]) / self.dt, matrix_to_rotvec(held[:3, :3] @ before[:3, :3].T) / self.dt))
            self.cart.resync(held[:3, 3], held[:3, :3], velocity)
            self._set_rk(held[:3, 3], held[:3, :3])
        self.moved = True

    # ---------------------------------------------------------------------------- the guard
    def cross_check(self, setpoint: Vector | None, actual: Vector) -> str | None:
        """None when what the controller reports fits what we commanded (or the set point a cycle or so
        before it), within the tolerances, by the convention it follows (:mod:`.convention`); else what
        disagrees.  ``setpoint``: the reported ASPos (rad; None when not sent), ``actual``: AIPos; under
        Cartesian corrections the reported RSol and RIst are checked instead."""
        recent = list(self.track)[-(self.link.report_lag_cycles + 1):]
        if self.space() == "joint":
            return self.check.joints(recent, self.window, setpoint, actual)
        rsol, rist = self._reported(False), self._reported(True)
        mine = None if rist is None else np.linalg.inv(self.actual_calibration) @ rist
        return self.check.pose([self.calibration @ pose for pose in recent], self.window, rsol, mine)

    def hold(self) -> None:
        """Stop changing the correction at once: the set point stays where the controller holds it."""
        if self.mode == "stream":
            self.mode, self.cursor = self.stream_space, None
        held = self.held()
        if self.space() == "joint":
            self.joint.reset(held)
            self.ak, self.rk = (held - self.q_ref) / _DEG, np.zeros(6)
        else:
            self.cart.reset(held[:3, 3], held[:3, :3])
            self._set_rk(held[:3, 3], held[:3, :3])
        self.moved = True

    def _limit(self) -> str | None:
        """Hold the proposed correction to the limits; a message when a stream had to stop for it."""
        held, before = self.track[-1], self.track[-2]
        if self.space() == "joint":
            want = self.q_ref + self.ak * _DEG
            step, axes = limit_joint_step(want - held, held - before, self._max_step, self._max_change)
            if not axes:
                return None
            for i in axes:
                self._clamped(AXES[i], float(want[i] - held[i]), float(held[i] - before[i]), float(step[i]), float(self._max_step[i]), float(self._max_change[i]))
            out = held + step
            self.ak = (out - self.q_ref) / _DEG
            if self.mode == "stream":
                return self._abandon_stream(out, step / self.dt, ", ".join(AXES[i] for i in axes))
            self.joint.resync(out, step / self.dt)
            return None
        want_p, want_r = self._rk_pose()
        shift, shift_clamped = limit_vector_step(want_p - held[:3, 3], held[:3, 3] - before[:3, 3], *self._linear)
        turn_wanted = matrix_to_rotvec(want_r @ held[:3, :3].T)
        turn, turn_clamped = limit_vector_step(turn_wanted, matrix_to_rotvec(held[:3, :3] @ before[:3, :3].T), *self._angular)
        if not (shift_clamped or turn_clamped):
            return None
        if shift_clamped:
            self._clamped("TCP translation", float(np.linalg.norm(want_p - held[:3, 3])) * 1000, math.nan, float(np.linalg.norm(shift)) * 1000, self._linear[0] * 1000, self._linear[1] * 1000, "mm")
        if turn_clamped:
            self._clamped("TCP rotation", float(np.linalg.norm(turn_wanted)), math.nan, float(np.linalg.norm(turn)), self._angular[0], self._angular[1])
        p, r = held[:3, 3] + shift, rotvec_to_matrix(turn) @ held[:3, :3]
        self._set_rk(p, r)
        velocity = np.concatenate((shift, turn)) / self.dt
        if self.mode == "stream":
            return self._abandon_stream(np.concatenate((p, matrix_to_abc(r))), velocity, "the TCP")
        self.cart.resync(p, r, velocity)
        return None

    def _clamped(self, what: str, wanted: float, before: float, sent: float, speed: float, change: float, unit: str = "deg") -> None:
        self.clamped += 1
        self.clamps[what] = self.clamps.get(what, 0) + 1
        scale = (lambda v: v) if unit == "mm" else math.degrees
        previous = "" if math.isnan(before) else f" after a step of {scale(before):.4f} {unit}"
        self._warn(
            f"limit {what}",
            f"limiter: {what} asked to step {scale(wanted):.4f} {unit} in one cycle{previous}; held to {scale(sent):.4f} {unit} "
            f"(at most {scale(speed):.4f} {unit} per cycle, changing by {scale(change):.5f} {unit} per cycle); the step asked for was not sent",
        )

    def _abandon_stream(self, here: Vector, velocity: Vector, what: str) -> str:
        assert self.cursor is not None and self.path is not None
        where = self.path.where(min(len(self.path), self.cursor.point) - 1)
        self.cursor, self.mode = None, self.stream_space
        if self.stream_space == "joint":
            self.joint.reset(here, velocity)
            self.joint.halt()
        else:
            self.cart.reset(here[:3], abc_to_matrix(*here[3:]), velocity)
            self.cart.halt()
        return f"{where}: the stream was stopped, its step exceeded the limits of {what} (see the limiter warning)"

    # ---------------------------------------------------------------------------- stepping
    def step(self) -> str | None:
        """One cycle: the generator or the stream proposes, the limiter disposes.  A message when a
        stream had to be stopped, or a proposal that is not a number made the robot brake."""
        if self.mode == "stream":
            self._step_stream()
        elif self.mode == "joint":
            if not self.joint.done:
                self.joint.step()
                self.ak = (self.joint.position - self.q_ref) / _DEG
                self.moved = True
        elif not self.cart.done:
            self.cart.step()
            self._set_rk(self.cart.position, self.cart.rotation)
        if not np.isfinite(self.ak if self.space() == "joint" else self.rk).all():
            return self._brake_instead()
        return self._limit()

    def _brake_instead(self) -> str:
        """A proposed correction that is not a number is never sent (NaN passes every comparison of
        the limiter): the motion brakes instead, from the set point the controller holds, at the
        speed it holds it with, within the limits; the command stops and the reason is reported."""
        joint = self.space() == "joint"
        bad = ", ".join(f"{n} {v}" for n, v in zip(AXES if joint else _RK_NAMES, self.ak if joint else self.rk) if not math.isfinite(v))
        self.cursor, self.mode = None, self.space()
        self._catch_up()  # the generator on the held set point, at the speed it is held with
        if joint:
            self.joint.halt()
            self.joint.step()
            self.ak = (self.joint.position - self.q_ref) / _DEG
        else:
            self.cart.halt()
            self.cart.step()
            self._set_rk(self.cart.position, self.cart.rotation)
        self._limit()
        text = f"the {'axis' if joint else 'Cartesian'} correction computed for this cycle is not a number ({bad}); it was not sent, the robot brakes from its set point"
        self._warn("not a number", text)
        return text

    def _set_rk(self, p: Vector, r: Matrix) -> None:
        a, b, c = matrix_to_abc(r @ self.base[:3, :3].T)
        d = (p - self.base[:3, 3]) * 1000.0
        self.rk = np.array([d[0], d[1], d[2], a / _DEG, b / _DEG, c / _DEG])
        self._cart_joints = None
        self.moved = True

    def _rk_pose(self) -> tuple[Vector, Matrix]:
        return self.base[:3, 3] + self.rk[:3] / 1000.0, abc_to_matrix(*(self.rk[3:] * _DEG)) @ self.base[:3, :3]

    def _step_stream(self) -> None:
        assert self.cursor is not None
        point = self.cursor.advance()
        if self.stream_space == "joint":
            self.joint.position = point.copy()
            self.ak = (point - self.q_ref) / _DEG
            self.moved = True
        else:
            self.cart.position = point[:3].copy()
            self.cart.rotation = abc_to_matrix(*point[3:])
            self._set_rk(self.cart.position, self.cart.rotation)
        if self.cursor.done:
            # The path ends at rest; its end stays the target, so a catch-up still gets there.
            self.cursor, self.mode = None, self.stream_space
            if self.mode == "joint":
                self.joint.reset(point)
                self.joint.set_target(point, self.vmax, self.amax)
            else:
                self.cart.reset(point[:3], abc_to_matrix(*point[3:]))
                self.cart.set_target(point[:3], abc_to_matrix(*point[3:]), self._cart_limits((math.inf,) * 4))

    def replies(self) -> tuple[Vector, Vector]:
        """The axis and Cartesian correction values of this cycle's reply (protocol units)."""
        ak = self.ak_model.reply_for(self.ak)
        rk = self.rk_model.reply_for(self.rk, cartesian_increment)
        if self.relative:
            # Increments travel with 6 decimals and add up on the controller: add up the same ones.
            ak, rk = np.round(ak, PACKET_DECIMALS), np.round(rk, PACKET_DECIMALS)
        cursor = (self.cursor.position, self.cursor.rate) if self.mode == "stream" and self.cursor is not None else None
        self._reply = (ak, rk, cursor)
        if self.moved:
            self.moved, self.quiet = False, 0
        else:
            self.quiet += 1
        return ak, rk

    def withheld(self) -> None:
        """This cycle's reply was not sent after all."""
        self._reply = (None, None, None)

    # ---------------------------------------------------------------------------- commands
    def idle(self) -> bool:
        if self.mode == "stream":
            return False
        return self.joint.done if self.mode == "joint" else self.cart.done

    def set_override(self, rate: float) -> None:
        """The operator's speed override (0..1): every move and stream of this robot at that share of its speed, on
        its path, the change within the axes' accelerations (0: braked to rest there, target kept); refused if it is
        not a share."""
        if not 0.0 <= rate <= 1.0:
            self._warn("speed override", f"a speed override of {rate!r} is no share of the speed; ignored")
            return
        self.override = self.joint.scale = self.cart.scale = rate
        if self.cursor is not None:
            self.cursor.cap = rate

    def launch_joint(self, target: Vector, speed: Vector, accel: float) -> None:
        """Aim the joint generator at ``target``, no faster than the axes allow."""
        self.fold_to("joint")
        self.joint.set_target(target, np.minimum(speed, self.vmax), np.minimum(accel, self.amax))

    def _cart_limits(self, limits: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        link = self.link
        caps = (link.max_linear_speed, link.max_linear_accel, link.max_angular_speed, link.max_angular_accel)
        return tuple(min(a, b) for a, b in zip(limits, caps))  # type: ignore[return-value]

    def launch_cart(self, position: Vector, rotation: Matrix, limits: tuple[float, float, float, float]) -> None:
        """Aim the Cartesian generator at a pose, within the link's Cartesian limits."""
        self.fold_to("cart")
        self.cart.set_target(position, rotation, self._cart_limits(limits))

    def launch_stream(self, path: ToolPath, limits: Vector) -> str | None:
        """Play a checked path from here; a message when its first point is out of reach of one cycle.

        ``limits[0]``/``limits[2]`` bound the first Cartesian step (m/s, rad/s).  A path whose start
        is not at rest is entered with a ramp (see :class:`StreamCursor`), never with a jump.
        """
        space = "joint" if path.space == "joint" else "cart"
        self.fold_to(space)
        first = path.points[0]
        dt = self.dt
        if space == "joint":
            start = self.joint.position.copy()
            too_far = bool(np.any(np.abs(first - start) / dt > self.vmax * (1 + 1e-9)))
            budget = self._max_change
        else:
            start = np.concatenate((self.cart.position, matrix_to_abc(self.cart.rotation)))
            shift = float(np.linalg.norm(first[:3] - start[:3])) / dt
            turn = rotation_angle(abc_to_matrix(*first[3:]) @ self.cart.rotation.T) / dt
            too_far = shift > limits[0] * (1 + 1e-9) or turn > limits[2] * (1 + 1e-9)
            budget = np.array([self._linear[1]] * 3 + [self._angular[1]] * 3)
        if too_far:
            return f"{path.where(0)}: the first point is more than one cycle's motion away from the robot"
        points = np.vstack((start, path.points))
        ramp = ramp_rate(path.points, budget)
        opening = np.abs(points[1] - points[0])
        if len(points) > 2:
            opening = np.maximum(opening, np.abs(points[2] - 2 * points[1] + points[0]))
        moving = opening > STILL
        ratio = float(np.min(budget[moving] / opening[moving])) if np.any(moving) else math.inf
        self.cursor = StreamCursor(points, ramp, min(self.override, 1.0 if ratio >= 1.0 else max(0.0, ratio - ramp)))
        self.cursor.cap = self.override
        self.path, self.stream_space, self.mode = path, space, "stream"
        self._applied_cursor = (0.0, 0.0)
        return None

    def stream_progress(self) -> float:
        """How far along its path the latest stream has commanded the set point: a point index from 0,
        fractional; its last point once all are sent.  What a resume after a halt goes on from."""
        if self.path is None:
            return 0.0
        if self.mode == "stream" and self.cursor is not None:
            return max(0.0, self.cursor.position - 1.0)  # the cursor's row 0 is where the robot stood
        return float(len(self.path) - 1)

    def halt(self) -> None:
        """Brake to rest at the current limits; a stream hands its speed to the generator first."""
        if self.mode == "stream" and self.cursor is not None:
            here, velocity = self.cursor.at(self.cursor.position), self.cursor.velocity(self.dt)
            if self.stream_space == "joint":
                self.joint.reset(here, velocity)
            else:
                self.cart.reset(here[:3], abc_to_matrix(*here[3:]), np.concatenate((velocity[:3], np.zeros(3))))
            self.cursor, self.mode = None, self.stream_space
        if self.mode == "joint":
            self.joint.halt()
        else:
            self.cart.halt()

    def stop(self) -> None:
        """RSI_MOVECORR ended or packets stopped: forget targets and stream where they are."""
        self.joint.reset(self.joint.position)
        self.cart.reset(self.cart.position, self.cart.rotation)
        if self.mode == "stream":
            self.cursor, self.mode = None, self.stream_space

    def fold_to(self, space: str) -> None:
        """Hand the corrections to the other space's generator without moving the set point.

        To joints: the axis correction takes the commanded pose's joints and the Cartesian one
        returns to zero in the same packet.  To Cartesian: corrections are measured from the
        commanded joints' pose (our kinematics); the controller's RSol of that moment gives the
        offset between its model and ours, for the cross-check only.
        """
        if space == self.mode:
            return
        if space == "joint":
            q = self._cart_joints if self._cart_joints is not None else self.solve_cart_joints()
            self.joint.reset(q)
            self.ak, self.rk = (q - self.q_ref) / _DEG, np.zeros(6)
            self._fold_point = q.copy()
            self.track = deque([q.copy()] * self._depth, maxlen=self._depth)
            self.window = deque([q.copy()], maxlen=self._span)
        else:
            q = self.q_ref + self.ak_model.total * _DEG
            self.base = self.arm.fk(q)
            rsol, rist = self._reported(False), self._reported(True)
            self.calibration = np.eye(4) if rsol is None else rsol @ np.linalg.inv(self.base)
            self.actual_calibration = np.eye(4) if rist is None else rist @ np.linalg.inv(self.base)
            self.cart.reset(self.base[:3, 3], self.base[:3, :3])
            self.ak, self.rk = self.ak_model.total.copy(), np.zeros(6)
            self.track = deque([self.base.copy()] * self._depth, maxlen=self._depth)
            self.window = deque([self.base.copy()], maxlen=self._span)
        self.mode = space
        self.moved = True

    def solve_cart_joints(self) -> Vector:
        """The joints of the commanded pose (nearest the last commanded joints); kept until it moves."""
        pose = self.held() if self.space() == "cart" else self.arm.fk(self.commanded)
        q = self.arm.ik(pose, self.commanded)
        self._cart_joints = q if q is not None else self.commanded.copy()
        self.commanded = self._cart_joints.copy()
        return self._cart_joints

    def update_commanded(self) -> None:
        """After the reply: the commanded joints, for the application (IK only once a Cartesian move rests)."""
        if self.space() == "joint":
            self.commanded = self.q_ref + self.ak * _DEG
        elif self.mode == "cart" and self.cart.done and self._cart_joints is None:
            self.solve_cart_joints()
