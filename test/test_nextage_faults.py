"""Fault injection in the Nextage simulator: the text form, and faults striking mid-motion."""
from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core_functions.primitives import Dwell, FullBodyMove, MoveCartesian, MoveJoints, Vision
from core_functions.robots import NEXTAGE_OPEN
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.nextage_sim.backend import NextageSimBackend
from robot_bridges.nextage_sim.faults import FaultSpec, parse_fault

Run = Callable[[Callable[[Clock], Coroutine[Any, Any, None]]], None]
LEFT = NEXTAGE_OPEN.group("left_arm").joint_names


def _left(backend: NextageSimBackend) -> np.ndarray:
    names, values = backend.joint_state()
    return np.array([values[names.index(n)] for n in LEFT])


# -------------------------------------------------------------------------- text form
def test_parse_fault_forms_and_defaults() -> None:
    assert parse_fault("right_arm:joint_limit@0.5") == FaultSpec("right_arm", FaultKind.JOINT_LIMIT, 0.5)
    assert parse_fault(" left_arm : COLLISION @ 0.25 ") == FaultSpec("left_arm", FaultKind.COLLISION, 0.25)
    assert parse_fault("left_arm:unreachable") == FaultSpec("left_arm", FaultKind.UNREACHABLE, 0.0)
    assert parse_fault("torso_head:controller").after == 0.5
    assert str(parse_fault("left_arm:vision@1")) == "left_arm:vision@1"


@pytest.mark.parametrize(
    "text, message",
    [
        ("right_arm", "is not <group>:<kind>"),
        ("right_arm:melted", "unknown fault kind 'melted'"),
        ("right_arm:joint_limit@half", "'half' is not a number"),
        ("right_arm:joint_limit@1.5", "within [0, 1]"),
        ("right_arm:joint_limit@nan", "within [0, 1]"),
        ("x" * 300, "longer than"),
    ],
)
def test_parse_fault_rejects_bad_text_clearly(text: str, message: str) -> None:
    with pytest.raises(ValueError) as info:
        parse_fault(text)
    assert message in str(info.value)


@given(st.text(max_size=80))
def test_parse_fault_never_fails_other_than_with_value_error(text: str) -> None:
    try:
        spec = parse_fault(text)
    except ValueError:
        return
    assert 0.0 <= spec.after <= 1.0 and spec.group


# --------------------------------------------------------------------- in the backend
def test_injected_joint_limit_stops_the_next_motion_half_way(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        backend.inject_fault("left_arm", FaultKind.JOINT_LIMIT, after=0.5)
        await backend.execute("right_arm", MoveJoints((0.0,) * 6))  # another group: not affected
        start = _left(backend)
        goal = start + np.array([0.8, -0.4, 0.4, 0.0, 0.0, 0.0])
        t0 = clock.now()
        with pytest.raises(BridgeError) as info:
            await backend.execute("left_arm", MoveJoints(tuple(goal)))
        assert info.value.kind is FaultKind.JOINT_LIMIT
        assert "LARM_JOINT0 at " in str(info.value) and "50% into move_joints" in str(info.value)
        full = 0.8 / 1.0 + 1.0 / 1.5  # the limiting joint's trapezoid
        assert clock.now() - t0 == pytest.approx(full / 2, abs=1e-6)
        np.testing.assert_allclose(_left(backend), (start + goal) / 2, atol=1e-9)  # really half-way (symmetric profile)
        result = await backend.execute("left_arm", MoveJoints(tuple(goal)))  # consumed: the retry works
        np.testing.assert_allclose(result.positions, goal)

    run_sim(main)


def test_injected_unreachable_fails_the_next_cartesian_move_before_moving(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock, faults=[parse_fault("right_arm:unreachable")])
        await backend.execute("right_arm", MoveJoints((0.05,), joint_names=("RARM_JOINT0",), relative=True))
        before = backend.joint_state()
        tcp = backend.tcp_pose("right_arm")
        assert tcp is not None
        with pytest.raises(BridgeError) as info:
            await backend.execute("right_arm", MoveCartesian(tcp.translated(0.02, 0, 0)))
        assert info.value.kind is FaultKind.UNREACHABLE and "no IK solution for TCP target" in str(info.value)
        assert backend.joint_state() == before
        assert backend.pending_faults == ()

    run_sim(main)


def test_injected_unreachable_part_way_along_a_line(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        backend.inject(FaultSpec("left_arm", FaultKind.UNREACHABLE, 0.5))
        start = backend.tcp_pose("left_arm")
        assert start is not None
        target = start.translated(0.0, 0.0, 0.1)
        with pytest.raises(BridgeError) as info:
            await backend.execute("left_arm", MoveCartesian(target, "linear"))
        assert info.value.kind is FaultKind.UNREACHABLE
        now = backend.tcp_pose("left_arm")
        assert now is not None and now.z == pytest.approx(start.z + 0.05, abs=1e-4)  # stopped half-way on the line

    run_sim(main)


def test_injected_vision_fault_and_full_body_fault(run_sim: Run) -> None:
    async def main(clock: Clock) -> None:
        backend = NextageSimBackend(clock)
        tcp = backend.tcp_pose("left_arm")
        assert tcp is not None
        backend.inject_fault("left_arm", FaultKind.VISION, after=1.0)
        with pytest.raises(BridgeError) as vision:
            await backend.execute("left_arm", Vision("locate", "hole", nominal=tcp.translated(0.1, 0, 0)))
        assert vision.value.kind is FaultKind.VISION
        backend.inject_fault("right_arm", FaultKind.COLLISION, after=0.25)
        await backend.execute("right_arm", Dwell(0.2))  # a dwell is no motion: the fault waits
        names = NEXTAGE_OPEN.joint_names
        off = NEXTAGE_OPEN.poses["off"]
        task = asyncio.ensure_future(backend.execute("torso_head", FullBodyMove(names, tuple(off[n] for n in names))))
        with pytest.raises(BridgeError) as collision:
            await task
        assert collision.value.kind is FaultKind.COLLISION and "right_arm" in str(collision.value)
        names_now, values = backend.joint_state()
        moved = values[names_now.index("LARM_JOINT1")]
        assert math.radians(-140) < moved < -1e-3  # part-way to the off pose

    run_sim(main)
