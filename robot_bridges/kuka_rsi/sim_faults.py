"""What the simulated KR C4 does wrong on purpose: faults on the network and quirks of what it reports.

An external system is only as good as its handling of a controller that is late, loses packets, or reports what
it likes; the simulator reproduces both, reproducibly from a seed, so the bridge's handling can be tested and
demonstrated.  :class:`Faults` act on the network side (``sim_network``: jitter, lost packets, garbage, replies
dropped), :class:`Quirks` on the controller model (``krc_model``: a frozen or drifting set point, ROS-I's
spellings).  A second sender on the controller's host is :class:`~.spoofer.Flood`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Faults:
    """Faults to inject, reproducibly from ``seed``."""

    jitter_ms: float = 0.0  # real-time mode: each send is moved by up to +- this
    loss: float = 0.0  # probability that a packet is never sent (the cycle is then late)
    garbage: float = 0.0  # probability that a garbage datagram precedes a packet
    seed: int = 0
    drop: float = 0.0  # probability that a valid reply is discarded on arrival (the cycle is then late)

    def __post_init__(self) -> None:
        if not (0.0 <= self.loss <= 1.0 and 0.0 <= self.garbage <= 1.0 and 0.0 <= self.drop <= 1.0 and self.jitter_ms >= 0.0):
            raise ValueError(f"fault probabilities must lie in [0, 1] and jitter be >= 0: {self}")


@dataclass(frozen=True)
class Quirks:
    """How a controller reports: the peers an external system must not take at their word."""

    frozen_setpoint: bool = False  # ASPos and RSol keep reporting the start pose (ROS-I's kuka_rsi_simulator)
    drift_axis: int = 0  # 1..6: the reported ASPos (and RSol) of this axis drifts from the real set point ...
    drift_deg: float = 0.0  # ... by this much per cycle while RSI_MOVECORR runs
    root_attribute: str = "Type"  # how <Rob> spells its type attribute (ROS-I: "TYPE")
    ipoc_step: int | None = None  # IPOC increment per cycle; None: the cycle in ms, as a KR C4 (ROS-I: 1)
    drift_actual: bool = False  # the drift shows in the actual axes (AIPos, RIst) instead of the set point
    zero_cartesian: bool = False  # RIst and RSol read zero in every packet (ROS-I's kuka_rsi_simulator)

    def __post_init__(self) -> None:
        if not 0 <= self.drift_axis <= 6 or not math.isfinite(self.drift_deg):
            raise ValueError(f"drift axis is 1..6 (0: none) and the drift finite: {self}")
        if not self.root_attribute.isidentifier() or (self.ipoc_step is not None and self.ipoc_step < 1):
            raise ValueError(f"the root attribute must be a name and the IPOC step >= 1: {self}")

    @staticmethod
    def parse_drift(text: str) -> tuple[int, float]:
        """``A3:0.01`` (or ``3:0.01``): axis and degrees per cycle."""
        axis, sep, value = text.partition(":")
        axis = axis.upper().removeprefix("A")
        if not sep or not axis.isdigit():
            raise ValueError(f"drift is AXIS:DEG_PER_CYCLE, e.g. A3:0.01, got {text!r}")
        return int(axis), float(value)
