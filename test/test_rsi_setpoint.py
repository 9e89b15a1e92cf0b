"""What the controller holds of our replies, from its Delay counter and IPOC alone."""
from __future__ import annotations

import numpy as np
import pytest

from robot_bridges.kuka_rsi.setpoint import CorrectionModel, CycleAccount, cartesian_increment, compose_cartesian


@pytest.mark.parametrize(
    ("ipocs", "delays", "expected"),
    [
        ((0, 4, 8), (0, 0, 0), [(True, 0), (True, 0)]),  # every reply on time
        ((0, 4, 8), (0, 1, 1), [(False, 1), (True, 0)]),  # our reply to the first packet came late
        ((0, 8), (0, 1), [(True, 1)]),  # ours was on time; the packet between never reached us (or went stale)
        ((0, 12), (0, 3), [(False, 3)]),  # ours was late, and the two packets after it were never answered
        ((0, 0), (0, 1), [(False, 1)]),  # ROS-I's simulator repeats the IPOC after a timeout
    ],
)
def test_the_account_tells_applied_replies_from_held_cycles(ipocs: tuple[int, ...], delays: tuple[int, ...], expected: list[tuple[bool, int]]) -> None:
    account = CycleAccount(None, 4)
    account.reset(ipocs[0], delays[0])
    assert [account.account(i, d) for i, d in zip(ipocs[1:], delays[1:])] == expected


def test_the_ipoc_step_is_learned_from_packets_on_time() -> None:
    """ROS-I's simulator counts packets (1 per cycle), not milliseconds."""
    account = CycleAccount(None, 4)
    account.reset(100, 0)
    assert account.account(101, 0) == (True, 0) and account.step == 1
    assert account.account(103, 1) == (True, 1)  # two cycles: ours applied, one never answered


@pytest.mark.parametrize(("relative", "holdon", "total"), [(False, True, 2.0), (False, False, 0.0), (True, True, 7.0), (True, False, 5.0)])
def test_held_cycles_follow_holdon_and_the_correction_mode(relative: bool, holdon: bool, total: float) -> None:
    model = CorrectionModel([holdon], relative)
    model.cycle(np.array([3.0]) if relative else np.array([1.0]))
    model.cycle(np.array([2.0]))
    model.cycle(None)  # a cycle without our reply: the last value again (HOLDON=1) or zero
    assert model.total[0] == pytest.approx(total)


def test_cartesian_increments_compose_back_to_their_target() -> None:
    total = np.array([10.0, -5.0, 2.0, 30.0, -20.0, 45.0])
    desired = np.array([12.0, -4.0, 2.5, 31.0, -19.0, 44.0])
    assert compose_cartesian(total, cartesian_increment(desired, total)) == pytest.approx(desired)
