"""``/joint_states`` as the ros2-control back end trusts it: every sample checked before it counts.

The controller's joint states are the only word on where the arm is, so what cannot be true is a
fault rather than a position: a sample without a number for a joint the back end drives, a value
that is not finite, a joint that moved farther since the last sample than its URDF speed allows in
the time between them (a jump: another robot's states, a restarted driver, a broken encoder), and
states that stop coming (:meth:`JointFeed.stale`).  Once a fault is seen it stays: the back end
reports it and moves nothing until it is rebuilt.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from node_transport.clock import Clock
from node_transport.msgs import JointState

#: rad a joint may move beyond what its speed allows between two samples (quantisation, timing jitter of the stamps).
JUMP_SLACK = 0.02
#: how much faster than its URDF limit a joint may seem to move between two samples before it is a jump.
JUMP_FACTOR = 1.5
#: s: how much later than its stamp says a sample may be delivered (a burst after a network hiccup).
MAX_JITTER = 0.1


@dataclass(frozen=True)
class Sample:
    positions: dict[str, float]
    received: float  # the back end's clock
    stamp: float  # the message's header stamp (s), 0.0 when the publisher sets none


class JointFeed:
    """The latest trusted positions of the joints in ``speeds`` (joint name -> rad/s limit)."""

    def __init__(self, clock: Clock, speeds: Mapping[str, float]) -> None:
        self.clock = clock
        self.speeds = dict(speeds)
        self.latest: Sample | None = None
        self.joints: dict[str, tuple[float, float, float]] = {}  # name -> (position, received, stamp)
        self.fault: str | None = None
        self.count = 0

    def on_message(self, msg: JointState) -> None:
        if self.fault is not None:
            return
        now = self.clock.now()
        if len(msg.name) != len(msg.position):
            self.fault = f"joint_states: {len(msg.name)} names but {len(msg.position)} positions"
            return
        given = dict(zip(msg.name, msg.position))
        ours = {name: float(given[name]) for name in self.speeds if name in given}
        if not ours:
            return  # another robot's joints on the same topic (a gripper's broadcaster): not ours
        bad = [name for name, value in ours.items() if not math.isfinite(value)]
        if bad:
            self.fault = f"joint_states: {bad[0]} is {ours[bad[0]]} (not a number the arm can be at)"
            return
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for name, value in ours.items():  # each joint against its own last sample: a driver may publish groups apart
            last = self.joints.get(name)
            if last is None:
                continue
            before, received, stamped_before = last
            # samples can arrive in bursts (a network's jitter): the time between them is what their stamps say,
            # or what the back end saw where the publisher stamps nothing -- but never more than the delivery could
            # have delayed them: stamps do not excuse a jump
            stamped = stamp - stamped_before if stamp > 0.0 and stamped_before > 0.0 else 0.0
            elapsed = max(0.0, now - received, min(stamped, now - received + MAX_JITTER))
            allowed = self.speeds[name] * JUMP_FACTOR * elapsed + JUMP_SLACK
            if abs(value - before) > allowed:
                self.fault = (f"joint_states: {name} jumped {abs(value - before):.4f} rad in {elapsed:.3f} s (at most {allowed:.4f} "
                              f"at its speed limit): the robot's state cannot be trusted")
                return
        for name, value in ours.items():
            self.joints[name] = (value, now, stamp)
        if len(self.joints) == len(self.speeds):  # every joint heard of: the oldest one says how fresh the whole is
            self.latest = Sample({n: v for n, (v, _, _) in self.joints.items()}, min(r for _, r, _ in self.joints.values()), stamp)
            self.count += 1

    def age(self) -> float:
        return math.inf if self.latest is None else self.clock.now() - self.latest.received

    def stale(self, timeout: float) -> str | None:
        """Why the feed cannot be trusted now (a fault, or no sample for ``timeout`` s), or None."""
        if self.fault is not None:
            return self.fault
        if self.latest is None:
            return "no joint_states received for the arm's joints"
        age = self.age()
        if age > timeout:
            return f"joint_states stopped: the last one is {age:.2f} s old (state_timeout {timeout:g} s)"
        return None
