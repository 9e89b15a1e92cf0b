"""Shared fixtures: simulated time, a local transport, and hypothesis profiles."""
from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Coroutine, Iterator
from typing import Any, TypeVar

import pytest
from dds_domain import domain_env
from hypothesis import HealthCheck, settings

from node_transport.clock import Clock, run_with_clock, simulated_clock

T = TypeVar("T")

settings.register_profile("ci", deadline=None, max_examples=200, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


#: Test files whose point is real time (the KUKA RSI 4 ms loop and its simulated controller on the wall clock): under
#: pytest-xdist (README's ``-n auto --dist loadgroup``) they share one worker, so no two real-time loops race each
#: other for the cores; the rest of the suite spreads over the workers.
REAL_TIME_FILES = frozenset({
    "test_rsi_backend.py", "test_rsi_busy_computer.py", "test_rsi_linear_recording.py", "test_rsi_loop.py", "test_rsi_node.py",
    "test_rsi_peer.py", "test_rsi_simulator.py", "test_rsi_streaming.py", "test_rsi_tiny_values.py", "test_rsi_trust.py",
    "test_rsi_conventions.py", "test_rsi_signals.py", "test_speed_override_kuka.py",
    "test_mixed_cell.py",  # the mixed cell's KUKA: the simulated KR C4 on the wall clock
    "test_dds_follow_joint_trajectory.py", "test_follow_joint_trajectory_ros.py",  # their KUKA cases: the simulated KR C4 on the wall clock
    "test_cell_group_names_run.py", "test_cell_group_names_studio.py", "test_cell_tf_placed_dds.py",  # side_by_side's KUKA over RSI
})


#: The longest tests that wait on something besides this computer's CPU -- a controller or a motion in real time, a
#: launch's processes, a timeout a child process waits out, a browser -- longest first, by file, ``file::test``
#: prefix or (LONG_ROWS) the command of a docs/faults.md row. pytest-xdist hands the work out in collection order:
#: started last, one of them is the suite's tail while the other workers sit idle; started first (after the real-time
#: group, the longest unit), it overlaps the rest.
LONG_FIRST = (
    "test_ros2_control_rivet.py",  # the rivet demonstrator on ros2-control: 49 s of motion, the controller's real time
    "test_cli_faults.py::test_row[181-", "test_cli_faults.py::test_row[124-",  # a 20 s and a 15 s timeout waited out
    "test_breakpoints_record.py", "test_app_model_scaling.py", "test_branches_run.py", "test_rivet_loop.py", "test_run_report.py",
    "test_studio_browser.py", "test_breakpoints_browser.py", "test_studio_3d.py", "test_studio_two_origins.py", "test_jog_browser.py",
    "test_studio_roles_browser.py", "test_studio_timeline.py", "test_studio_graphs.py", "test_paused_edit_browser.py",
    "test_rivet_async.py", "test_app_model_wire_fit.py", "test_dds_cdr.py", "test_breakpoints_studio.py",
)
LONG_ROWS = re.compile(r"test_cli_faults\.py::test_row\[\d+-launch-")  # a launch: processes started and waited on


def first_rank(item: pytest.Item) -> tuple[int, int]:
    """Where ``item`` goes in the order tests are handed out: the real-time group, the long tests longest first, the
    rest (each in collection order)."""
    if item.path.name in REAL_TIME_FILES:
        return (0, 0)
    where = f"{item.path.name}::{item.name}"
    ranks = [i for i, prefix in enumerate(LONG_FIRST) if where.startswith(prefix)]
    if ranks:
        return (1, ranks[0])
    return (2, 0) if LONG_ROWS.match(where) else (3, 0)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    """``-n auto``: one worker per core and one more. A good share of the suite waits rather than computes -- the KUKA
    RSI loop and the mixed cell on the wall clock, processes that a launch starts, timeouts a child process waits
    out, the browser -- and a core left idle meanwhile is time the suite takes; the extra worker fills it.
    PYTEST_XDIST_AUTO_NUM_WORKERS still decides where it is set (xdist's own rule)."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None  # xdist's hook reads it
    return len(os.sched_getaffinity(0)) + 1


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "xdist_group(name): tests pytest-xdist's --dist loadgroup runs on one worker")
    if getattr(config.option, "loadscopereorder", False):
        # loadgroup hands its units out biggest group first, then one test at a time in collection order: a long test
        # alone (a launch, a browser) would wait behind the groups. In collection order instead, which
        # pytest_collection_modifyitems makes longest first (first_rank).
        config.option.loadscopereorder = False


def shares_a_module_fixture(item: pytest.Item) -> bool:
    """Whether the test uses a module-scoped fixture: a set-up (a whole run, a started cell) made once for its file."""
    info = getattr(item, "_fixtureinfo", None)  # pytest's own record of the test's fixtures
    return info is not None and any(defs and defs[-1].scope == "module" for defs in info.name2fixturedefs.values())


@pytest.hookimpl(tryfirst=True)  # before xdist's worker reads the groups off the marks
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items[:] = sorted(items, key=first_rank)  # stable: a file's tests stay together and in order
    for item in items:
        if item.path.name in REAL_TIME_FILES:
            item.add_marker(pytest.mark.xdist_group("real_time"))
        elif item.get_closest_marker("xdist_group") is None and shares_a_module_fixture(item):
            # the tests sharing a module's set-up go to one worker, which makes it once: spread over the
            # workers, each would make it (xdist joins every group mark of a test, so only where it has none)
            item.add_marker(pytest.mark.xdist_group(f"shared_setup:{item.path.name}"))


@pytest.fixture(autouse=True)
def private_home(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test has a home and XDG folders of its own: the dry run's kept verdicts (cell_runner/dry_run/verdict_cache.py),
    the machines' default trajectory database, anything a program keeps per user. A test sees the program as a first
    run does, never what another test -- one running beside it on another xdist worker -- or the person running them
    kept, and leaves nothing in the real home."""
    base = tmp_path_factory.getbasetemp() / "homes" / hashlib.sha256(request.node.nodeid.encode()).hexdigest()[:16]
    home = base / "home"
    home.mkdir(parents=True, exist_ok=True)  # some programs (a browser) want it to exist
    monkeypatch.setenv("HOME", str(home))
    for name, folder in (("XDG_CACHE_HOME", "cache"), ("XDG_DATA_HOME", "data"), ("XDG_CONFIG_HOME", "config"), ("XDG_STATE_HOME", "state")):
        monkeypatch.setenv(name, str(base / folder))


@pytest.fixture
def run_sim() -> Callable[[Callable[[Clock], Coroutine[Any, Any, T]]], T]:
    """Run ``main(clock)`` on a fresh virtual-time loop: waits cost no wall time, runs are deterministic."""

    def run(main: Callable[[Clock], Coroutine[Any, Any, T]]) -> T:
        return run_with_clock(main, simulated_clock())

    return run


@pytest.fixture
def dds_env() -> Iterator[dict[str, str]]:
    """The environment of DDS participants in a domain no other test uses meanwhile, in this session or
    another on this host (dds_domain.py), on loopback only; the domain is given back when the test ends."""
    with domain_env() as env:
        yield env
