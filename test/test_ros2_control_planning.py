"""Properties of what the ros2-control back end sends and what it believes (hypothesis).

* Every trajectory :func:`time_path` and :func:`retime` make -- any path, any speed fraction, any
  recorded timing -- keeps every joint within its speed (segment by segment and at the points) and
  its acceleration, starts and ends at rest, and passes every point of the path: nothing sent to a
  controller asks more than the URDF allows, whatever the primitive asked.
* :class:`JointFeed` takes ``/joint_states`` from outside: whatever arrives -- names and positions of
  any length, NaN and infinities, jumps -- it never raises, never holds a value that is not finite,
  and never moves a joint farther between two accepted samples than its speed allows.
* :func:`remainder` (a resume) starts where the arm stands and ends at the path's end.
* A robot description from the graph, mangled anyhow, builds a model whose every joint has finite limits,
  or is refused in one line (:class:`UrdfError`); a DTD, an entity or 16 MiB are refused before parsing.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from node_transport.clock import Clock
from node_transport.msgs import Header, JointState, Time
from robot_bridges.ros2_control.feed import JUMP_FACTOR, JUMP_SLACK, MAX_JITTER, JointFeed
from robot_bridges.ros2_control.model import MAX_URDF_CHARS, UrdfError, UrdfModel
from robot_bridges.ros2_control.planning import ACCELERATION_WINDOW, Limits, remainder, retime, time_path

NAMES = ("j1", "j2", "j3")
LIMITS = Limits(NAMES, np.full(3, -3.0), np.full(3, 3.0), np.array([1.0, 2.0, 4.0]), np.array([2.0, 4.0, 8.0]))
joint = st.floats(-3.0, 3.0, allow_nan=False)
paths = st.lists(st.tuples(joint, joint, joint), min_size=1, max_size=12).map(np.array)
fractions = st.floats(0.01, 1.0)


def within(timed, fraction: float) -> None:  # noqa: ANN001 - a planning.Timed
    dt = np.diff(timed.times)
    assert np.all(dt > 0) and timed.times[0] == 0.0
    speed = LIMITS.velocity * fraction * (1 + 1e-6)
    assert np.all(np.abs(np.diff(timed.points, axis=0)) <= speed * dt[:, None] + 1e-12)
    assert np.all(np.abs(timed.velocities) <= speed)
    window = np.maximum(dt, ACCELERATION_WINDOW)[:, None]
    assert np.all(np.abs(np.diff(timed.velocities, axis=0)) / window <= LIMITS.acceleration * fraction * (1 + 1e-6))
    assert np.all(timed.velocities[0] == 0) and np.all(timed.velocities[-1] == 0)


@settings(max_examples=60, deadline=None)
@given(paths, fractions)
def test_a_timed_path_stays_within_the_limits_and_passes_every_point(path: np.ndarray, fraction: float) -> None:
    timed = time_path(path, LIMITS, fraction)
    within(timed, fraction)
    np.testing.assert_allclose(timed.points[0], path[0])
    np.testing.assert_allclose(timed.points[-1], path[-1], atol=1e-12)
    for point in path:
        assert float(np.min(np.max(np.abs(timed.points - point), axis=1))) < 1e-9, "every point of the path is a point of the trajectory"


@settings(max_examples=60, deadline=None)
@given(paths, st.lists(st.floats(0.0, 0.5), min_size=12, max_size=12), fractions)
def test_a_replay_is_never_faster_than_the_limits_whatever_its_recorded_times(path: np.ndarray, gaps: list[float], fraction: float) -> None:
    times = np.concatenate(([0.0], np.cumsum(np.array(gaps[: len(path) - 1]) + 1e-3)))
    timed = retime(times, path, LIMITS, fraction)
    within(timed, fraction if len(path) == 1 or times[-1] <= 0 else 1.0)
    np.testing.assert_allclose(timed.points[-1], path[-1], atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(paths, st.tuples(joint, joint, joint).map(np.array))
def test_a_resume_starts_where_the_arm_stands_and_ends_at_the_paths_end(path: np.ndarray, measured: np.ndarray) -> None:
    rest, nearest = remainder(path, measured)
    np.testing.assert_array_equal(rest[0], measured)
    np.testing.assert_array_equal(rest[-1], path[-1])
    assert 0 <= nearest < len(path)


class StepClock(Clock):
    """A clock the test moves by hand (the feed only reads ``now``)."""

    def __init__(self) -> None:
        super().__init__(1.0, simulated=True)
        self.t = 0.0

    def now(self) -> float:
        return self.t


names_st = st.lists(st.sampled_from(NAMES + ("other",)), max_size=5)
values = st.floats(allow_nan=True, allow_infinity=True, width=64)
messages = st.lists(st.tuples(st.floats(0.0, 0.2), names_st, st.lists(values, max_size=5), st.floats(0.0, 1e4)), max_size=30)


@settings(max_examples=100, deadline=None)
@given(messages)
def test_the_feed_never_raises_never_holds_a_non_number_and_never_accepts_a_jump(stream: list) -> None:  # noqa: ANN001
    clock = StepClock()
    feed = JointFeed(clock, dict(zip(NAMES, (1.0, 2.0, 4.0))))
    since: dict[str, tuple[float, float]] = {}  # joint -> (value accepted, when it was first accepted)
    for gap, names, positions, stamp in stream:
        clock.t += gap
        feed.on_message(JointState(Header(stamp=Time.from_seconds(stamp)), tuple(names), tuple(positions)))
        if feed.latest is None:
            continue
        for name, speed in zip(NAMES, (1.0, 2.0, 4.0)):
            value = feed.latest.positions[name]
            assert math.isfinite(value)
            before = since.get(name)
            if before is None or before[0] != value:
                if before is not None:  # a move since the value was first accepted: within the joint's speed
                    assert abs(value - before[0]) <= speed * JUMP_FACTOR * (clock.t - before[1] + MAX_JITTER) + JUMP_SLACK + 1e-9
                since[name] = (value, clock.t)


KR6 = (Path(__file__).resolve().parents[1] / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf").read_text()
edits = st.lists(st.tuples(st.integers(0, len(KR6)), st.integers(0, 40), st.text(alphabet='<>/="\' abcdefgijklmnoprstuvwxyz0123456789.-e&;!\x00', max_size=12)), max_size=4)


@settings(max_examples=80, deadline=None)
@given(edits)
def test_a_mangled_robot_description_builds_a_model_with_finite_limits_or_is_refused_in_one_line(changes: list) -> None:  # noqa: ANN001
    text = KR6
    for at, cut, insert in changes:
        text = text[:at] + insert + text[at + cut:]
    try:
        model = UrdfModel(text)
    except UrdfError as error:
        assert "\n" not in str(error)
        return
    for limits in model.ranges.values():
        assert math.isfinite(limits.lower) and math.isfinite(limits.upper) and limits.lower <= limits.upper and 0 < limits.velocity < math.inf


def test_a_description_with_a_doctype_or_beyond_the_size_limit_is_refused() -> None:
    for text, words in ((KR6.replace("<robot", "<!DOCTYPE r [<!ENTITY a 'b'>]><robot", 1), "<!DOCTYPE>"), (KR6 + " " * MAX_URDF_CHARS, "over the limit")):
        try:
            UrdfModel(text)
        except UrdfError as error:
            assert words in str(error)
        else:
            raise AssertionError("taken")
