"""A Cartesian jog's leg as a joint trajectory of its own: the TCP along (or about) an axis at its capped speed.

A back end's own straight-line move at a reduced speed fraction scales time, and so its acceleration by the
square of the fraction: at the jog's 10 % the Nextage's TCP took seconds to get going and averaged a few mm/s
over its legs.  Where the back end replays a joint trajectory and stops inside it (the Nextage simulator, KUKA
RSI), the jog plans the leg itself instead, by resolved rates on the robot's kinematic model (the collision
scene's, the URDF the back end publishes): the TCP's twist ramps at the robot's TCP acceleration up to the cap
and back to rest at the leg's end, and each step's joint motion is ``J+ v dt`` (damped near a singularity),
slowed so that no joint goes above its own 10 % -- near a singularity the TCP slows, the joints never speed up.
A step that would leave a joint's range ends the leg there; a leg that cannot make a step is refused naming the
joint.  The back end then checks the trajectory as any other: its limits, its collision sweep.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from core_functions.motion_profile import TcpLimits
from robot_bridges.backend import JointLimits
from robot_bridges.collision import CollisionScene

#: Damping of the least-squares inverse (m, rad): keeps a step finite at a singularity.
DAMPING = 1e-3
#: m: the scene's TCP and the back end's may differ by this much before the jog stops trusting the model.
AGREE = 1e-3


@dataclass(frozen=True)
class Leg:
    """A planned leg: the group's joints at each time (the first point: where it is)."""

    times: tuple[float, ...]
    points: tuple[tuple[float, ...], ...]


class ResolvedRates:
    """Plans Cartesian jog legs of one robot on its collision scene's kinematic model."""

    def __init__(self, scene: CollisionScene) -> None:
        self.scene = scene
        self.model = scene.model
        self.data = self.model.createData()

    def agrees(self, group: str, q: np.ndarray, tcp_position: Sequence[float]) -> bool:
        """Whether the model puts the group's TCP where the back end says it is (else: the back end's own legs)."""
        if group not in self.scene.tcps:
            return False
        return bool(np.linalg.norm(self._tcp(group, q)[:3, 3] - np.asarray(tcp_position)) <= AGREE)

    def plan(
        self, group: str, q: np.ndarray, joints: Sequence[str], limits: JointLimits, axis: np.ndarray, rotation: bool,
        speed_fraction: float, cartesian_speed: float, tcp: TcpLimits, seconds: float, period: float,
    ) -> Leg:
        """The leg from ``q`` (the scene's joint order) moving the TCP along (or about) the world ``axis`` for
        ``seconds`` at the jog's speed.  ValueError naming the joint when no step can be made."""
        order = [self.scene.joint_names.index(n) for n in joints]
        k = [limits.joint_names.index(n) for n in joints]
        caps = np.array([speed_fraction * limits.velocity[i] for i in k])
        lower, upper = np.array([limits.lower[i] for i in k]), np.array([limits.upper[i] for i in k])
        top = speed_fraction * tcp.angular_velocity if rotation else min(cartesian_speed, speed_fraction * tcp.linear_velocity)
        accel = tcp.angular_acceleration if rotation else tcp.linear_acceleration
        ramp_time = top / accel
        total = max(seconds, 2.0 * ramp_time)
        steps = max(1, math.ceil(total / period - 1e-9))
        current = np.array(q, dtype=float)
        times, points = [0.0], [tuple(float(current[i]) for i in order)]
        for n in range(1, steps + 1):
            t = min(n * period, total)
            middle = t - 0.5 * (t - times[-1])
            rate = top * min(1.0, middle / ramp_time, (total - middle) / ramp_time)
            twist = np.zeros(6)
            twist[3 if rotation else 0:6 if rotation else 3] = axis * rate
            jacobian = self._jacobian(group, current)[:, order]
            step = jacobian.T @ np.linalg.solve(jacobian @ jacobian.T + DAMPING ** 2 * np.eye(6), twist) * (t - times[-1])
            speeds = np.abs(step) / max(t - times[-1], 1e-12)
            over = float(np.max(speeds / caps))
            if over > 1.0:
                step /= over  # near a singularity: the TCP slows down, no joint goes past its cap
            moved = current[order] + step
            outside = [joints[i] for i in range(len(joints)) if not lower[i] <= moved[i] <= upper[i]]
            if outside:
                if len(points) == 1:
                    raise ValueError(f"jog: {outside[0]} would leave its range ({lower[joints.index(outside[0])]:.4f} .. "
                                     f"{upper[joints.index(outside[0])]:.4f} rad): it goes no further that way")
                break
            current[order] = moved
            times.append(t)
            points.append(tuple(float(v) for v in moved))
        return Leg(tuple(times), tuple(points))

    def _tcp(self, group: str, q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.model, self.data, q)
        frame = self.model.getFrameId(self.scene.tcps[group].frame)
        return np.asarray(self.data.oMf[frame].homogeneous @ self.scene.tcps[group].tool.matrix())

    def _jacobian(self, group: str, q: np.ndarray) -> np.ndarray:
        """The TCP point's 6 x n Jacobian in world axes (linear, then angular)."""
        frame = self.model.getFrameId(self.scene.tcps[group].frame)
        jacobian = np.array(pin.computeFrameJacobian(self.model, self.data, q, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
        placement = self.data.oMf[frame]
        offset = placement.rotation @ np.asarray(self.scene.tcps[group].tool.position)  # the flange to the TCP, in the world
        jacobian[:3] -= _skew(offset) @ jacobian[3:]  # v_tcp = v_flange + w x r
        return jacobian


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
