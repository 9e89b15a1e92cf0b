"""One robot controller as the external system knows it: address, RSI context, limits, tolerances.

The limits are the robot's (``core_functions.robots``: joint ranges and speeds) and the link's own
(accelerations, which KUKA does not publish, and Cartesian limits): every correction step is held
to them (:mod:`.guard`).  The set-point tolerances say how far the controller's reported set point
may lie from the one our replies put there before the external system stops trusting it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from core_functions.robots import KUKA_KR
from robot_bridges.kuka_rsi.config import FEEDBACK_KEYS, ConfigError, RsiConfig, RsiRoles, default_config
from robot_bridges.kuka_rsi.guard import ACCEL_TIME

_JOINTS = KUKA_KR.group("arm").joints


@dataclass(frozen=True)
class RobotLink:
    """One robot controller served by the loop."""

    name: str
    host: str  # the IP its packets come from (a name is resolved once, at start); packets from anywhere else are ignored
    port: int | None = None  # the port it sends from; None: the port of its first valid packet, pinned from then on
    config: RsiConfig | None = None  # None: the package's default configuration
    roles: RsiRoles = RsiRoles()
    correction_mode: str = "absolute"  # must match the RSI context: "absolute" or "relative"
    cycle_ms: int = 4
    joint_tolerance: float = 1e-4  # rad: a joint move is done when every actual axis is this close
    position_tolerance: float = 1e-4  # m: a Cartesian move is done when the actual TCP is this close
    rotation_tolerance: float = 1e-3  # rad
    settle_cycles: int = 500  # cycles after the generator stopped before "did not reach" is reported
    lower: tuple[float, ...] = tuple(j.lower for j in _JOINTS)
    upper: tuple[float, ...] = tuple(j.upper for j in _JOINTS)
    max_joint_speed: tuple[float, ...] = tuple(j.max_velocity for j in _JOINTS)  # rad/s
    max_joint_accel: tuple[float, ...] = tuple(j.max_velocity / ACCEL_TIME for j in _JOINTS)  # rad/s^2
    max_linear_speed: float = 2.0  # m/s of the TCP under Cartesian corrections
    max_linear_accel: float = 20.0  # m/s^2
    max_angular_speed: float = math.pi  # rad/s
    max_angular_accel: float = 10.0 * math.pi  # rad/s^2
    # How far the reported set point (ASPos; RSol under Cartesian corrections) may lie from the
    # commanded one; math.inf switches the cross-check off (never for a real robot).
    setpoint_tolerance_deg: tuple[float, ...] = (0.1,) * 6  # A1..A6
    tcp_tolerance_mm: float = 1.0
    tcp_tolerance_deg: float = 0.1
    report_lag_cycles: int = 1  # the report may show the set point of this many cycles before
    # Where the controller reports no set point that follows the corrections (none sent, or frozen at the
    # start), its actual axes must lie among the set points commanded over this many seconds: a servo's lag.
    follow_time: float = 0.1
    ipoc_step: int | None = None  # IPOC increment per cycle; None: learned (KR C4: the cycle in ms)

    def __post_init__(self) -> None:
        if self.correction_mode not in ("absolute", "relative"):
            raise ValueError(f"robot {self.name}: correction mode is 'absolute' or 'relative', not {self.correction_mode!r}")
        if self.cycle_ms not in (4, 12):
            raise ValueError(f"robot {self.name}: RSI runs at 4 ms or 12 ms, not {self.cycle_ms}")
        sixes = (self.lower, self.upper, self.max_joint_speed, self.max_joint_accel, self.setpoint_tolerance_deg)
        if any(len(values) != 6 for values in sixes):
            raise ValueError(f"robot {self.name}: joint limits, accelerations and tolerances need 6 values (A1..A6)")
        positive = (*self.max_joint_speed, *self.max_joint_accel, self.max_linear_speed, self.max_linear_accel, self.max_angular_speed, self.max_angular_accel)
        if not all(math.isfinite(v) and v > 0 for v in positive):
            raise ValueError(f"robot {self.name}: speed and acceleration limits must be finite and > 0")
        if not all(v > 0 for v in (*self.setpoint_tolerance_deg, self.tcp_tolerance_mm, self.tcp_tolerance_deg)):
            raise ValueError(f"robot {self.name}: set-point tolerances must be > 0 (math.inf: no cross-check)")
        if not 0.0 < self.follow_time <= 1.0:
            raise ValueError(f"robot {self.name}: follow_time must lie in (0, 1] s, got {self.follow_time}")
        if self.report_lag_cycles < 0 or (self.ipoc_step is not None and self.ipoc_step < 1):
            raise ValueError(f"robot {self.name}: report_lag_cycles must be >= 0 and ipoc_step >= 1")

    def rsi_config(self) -> RsiConfig:
        return self.config if self.config is not None else default_config()


#: The one value the external system cannot do without: where the axes are.
_ACTUAL_AXES = tuple(f"AIPos.A{i}" for i in range(1, 7))


def require_feedback(config: RsiConfig, name: str) -> None:
    """The external system needs its replies read (ONLYSEND FALSE) and the actual axes in every packet:
    without them it cannot know where the robot is, nor check what the controller does with its corrections.  Everything else a
    configuration may lack only switches off what needs it (:func:`feedback_gaps`)."""
    if config.onlysend:
        raise ConfigError(f"robot {name}: {config.source} has ONLYSEND TRUE; the robot would ignore every reply")
    missing = [k for k in _ACTUAL_AXES if not config.has_send(k)]
    if missing:
        raise ConfigError(
            f"robot {name}: {config.source} must send DEF_AIPos, the actual axes (missing {', '.join(missing[:6])}): "
            "without them the robot's position is unknown"
        )


def feedback_gaps(config: RsiConfig, roles: RsiRoles) -> tuple[str, ...]:
    """What the values a configuration does not send switch off, one sentence each (empty: nothing).

    Nothing here weakens the limiter: it measures every step from the set point the external system
    itself commanded, never from a value the controller reports.
    """
    sends = {k.split(".", 1)[0] for k in FEEDBACK_KEYS if config.has_send(k)}
    gaps: list[str] = []
    if "ASPos" not in sends:
        gaps.append(
            "no ASPos (the axes' set point): corrections count from the actual axes (AIPos) when RSI_MOVECORR begins, "
            "and the cross-check compares AIPos with the set points the bridge itself commanded"
        )
    if roles.cartesian(config):
        if "RSol" not in sends and "RIst" in sends:
            gaps.append("no RSol (the TCP's set point): under Cartesian corrections the cross-check compares RIst with the commanded poses")
        elif "RSol" not in sends:
            gaps.append("neither RSol nor RIst (the TCP): Cartesian corrections (RKorr) are off, linear moves impossible")
    if "RIst" not in sends:
        gaps.append("no RIst (the actual TCP): the TCP is worked out from the actual axes")
    return tuple(gaps)
