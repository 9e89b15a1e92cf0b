"""Every numeric setting has a finite range, is refused outside it in one line, and is documented with it.

The command-line and back-end option refusals are rows 140-159 of docs/faults.md
(test_cli_faults.py runs them); here: the table itself, the node parameters, and the docs.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cell_runner.bridge_nodes.kuka_rsi import declare_kuka_parameters
from cell_runner.bridge_nodes.nextage_sim import declare_nextage_parameters
from cell_runner.bridge_nodes.vplus import declare_vplus_parameters
from cell_runner.libraries import APPLICATION_FUNCTIONS
from core_functions.option_ranges import OPTIONS, SETTINGS, Range, RangeError, bounds, table
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.machine.group_machine import GroupMachine
from node_transport.clock import Clock, MAX_SPEED, MIN_SPEED, run_with_clock, simulated_clock
from node_transport.local import LocalTransport
from node_transport.port import TransportError
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.camera.ros_camera import attach_cameras
from robot_bridges.kuka_rsi.simulator import main as kuka_simulator
from robot_bridges.nextage_sim.backend import NextageSimBackend

ROOT = Path(__file__).resolve().parents[1]


def test_every_range_is_finite_and_the_speed_is_the_clocks() -> None:
    for (scope, name), entry in OPTIONS.items():
        allowed = entry.allowed
        assert math.isfinite(allowed.lower) and math.isfinite(allowed.upper) and allowed.lower < allowed.upper, name
        assert entry.where and entry.what, name
        assert not scope or scope in entry.where, f"{name} of {scope}: the docs' 'where' names its back end"
    assert len(OPTIONS) == len(SETTINGS)  # one entry per (scope, name)
    assert (bounds("speed").lower, bounds("speed").upper) == (MIN_SPEED, MAX_SPEED)


def test_a_name_two_back_ends_read_differently_has_a_range_for_each_and_no_default() -> None:
    """tolerance_mm is millimetres for both, within [0.01, 50] for V+ and [0.001, 100] for KUKA RSI; timeout is seconds
    for V+ and late packets for RSI: a reader must say whose it reads, and one that does not is a defect."""
    assert bounds("tolerance_mm", "vplus").describe() == "[0.01, 50] mm" and bounds("tolerance_mm", "kuka-rsi").describe() == "[0.001, 100] mm"
    assert bounds("timeout", "vplus").describe() == "[0.1, 600] s" and bounds("timeout", "kuka-rsi").describe() == "[1, 100000]"
    for name in ("tolerance_mm", "timeout"):
        with pytest.raises(KeyError, match=name):
            bounds(name)
    assert bounds("port", "vplus") == bounds("port")  # a shared setting is the same for every reader
    shown = [row[0] for row in table()]
    assert {"tolerance_mm (vplus)", "tolerance_mm (kuka-rsi)", "timeout (vplus)", "timeout (kuka-rsi)"} <= set(shown)


@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(), st.text(max_size=20)))
def test_a_value_is_either_in_its_range_or_refused_naming_it(value: Any) -> None:
    for (_, name), entry in OPTIONS.items():
        allowed = entry.allowed
        try:
            checked = allowed.check(name, value)
        except RangeError as error:
            message = str(error)
            assert message.startswith(f"{name} must be ") and allowed.describe() in message and "\n" not in message
        else:
            assert math.isfinite(checked) and allowed.lower <= checked <= allowed.upper
            assert not allowed.integer or checked.is_integer()
            assert not allowed.choices or checked in allowed.choices


def test_integer_settings_refuse_fractions_and_floats_refuse_text() -> None:
    assert Range(0, 10, integer=True).check("n", "3") == 3.0
    with pytest.raises(RangeError, match=r"^n must be a whole number in \[0, 10\], got '2.5'$"):
        Range(0, 10, integer=True).check("n", "2.5")
    with pytest.raises(RangeError, match=r"^t must be a number in \[0.1, 600\] s, got True$"):
        Range(0.1, 600, "s").check("t", True)


def test_a_setting_with_choices_takes_only_those_and_says_so() -> None:
    """The RSI cycle is 4 or 12 ms: 8 lies inside [4, 12] and is still no cycle a controller runs."""
    cycle = bounds("cycle")
    assert cycle.describe() == "4 or 12 ms"
    assert [cycle.contains(v) for v in (4, 8, 12, 4.5)] == [True, False, True, False]
    with pytest.raises(RangeError, match=r"^cycle must be 4 or 12 ms, got '8'$"):
        cycle.check("cycle", "8")
    assert Range(1, 3, choices=(1, 2, 3)).describe() == "1, 2 or 3"
    assert ("cycle", "4 or 12 ms") in [(row[0].strip("`"), row[1]) for row in table()]


# ------------------------------------------------------------------------------ node parameters
def _refusal(build: Any, parameters: dict[str, Any]) -> str:
    async def main(clock: Clock) -> str:
        transport = LocalTransport(clock)
        with pytest.raises(TransportError) as caught:
            build(transport, parameters)
        return str(caught.value)

    return run_with_clock(main, simulated_clock())


def _machine(transport: LocalTransport, parameters: dict[str, Any]) -> None:
    GroupMachine(transport.create_node("left_arm_machine", parameters={"group": "left_arm", "trajectory_db": ":memory:", **parameters}), APPLICATION_FUNCTIONS)


def _engine(transport: LocalTransport, parameters: dict[str, Any]) -> None:
    ExecutionEngine(transport.create_node("execution_engine", parameters=parameters), APPLICATION_FUNCTIONS.catalog(None))


def _bridge(transport: LocalTransport, parameters: dict[str, Any]) -> None:
    backend = NextageSimBackend(transport.clock)
    node = transport.create_node("nextage_sim_bridge", parameters=parameters)
    if "camera_timeout" in parameters:
        attach_cameras(node, backend)
    else:
        BridgeNode(node, backend)


def _simulator(transport: LocalTransport, parameters: dict[str, Any]) -> None:
    declare_nextage_parameters(transport.create_node("nextage_sim_bridge", parameters=parameters))


def _vplus(transport: LocalTransport, parameters: dict[str, Any]) -> None:
    declare_vplus_parameters(transport.create_node("vplus_bridge", parameters=parameters))


def _kuka(transport: LocalTransport, parameters: dict[str, Any]) -> None:
    declare_kuka_parameters(transport.create_node("kuka_rsi_bridge", parameters=parameters))


@pytest.mark.parametrize(
    ("build", "parameters", "message"),
    [
        (_machine, {"bridge_timeout": math.inf}, "/left_arm_machine: parameter 'bridge_timeout' must be a number in [0.1, 600] s, got inf"),
        (_machine, {"primitive_timeout": 1e308}, "/left_arm_machine: parameter 'primitive_timeout' must be a number in [1, 86400] s, got 1e+308"),
        (_machine, {"sync_timeout": 0.0}, "/left_arm_machine: parameter 'sync_timeout' must be a number in [0.1, 3600] s, got 0"),
        (_engine, {"startup_timeout": -1.0}, "/execution_engine: parameter 'startup_timeout' must be a number in [0.1, 3600] s, got -1"),
        (_engine, {"function_timeout": math.inf}, "/execution_engine: parameter 'function_timeout' must be a number in [1, 86400] s, got inf"),
        (_engine, {"service_timeout": math.nan}, "/execution_engine: parameter 'service_timeout' must be a number in [0.1, 600] s, got nan"),
        (_bridge, {"state_period": 1e308}, "/nextage_sim_bridge: parameter 'state_period' must be a number in [0.001, 1] s, got 1e+308"),
        (_bridge, {"stop_timeout": math.inf}, "/nextage_sim_bridge: parameter 'stop_timeout' must be a number in [0.1, 600] s, got inf"),
        (_bridge, {"camera_timeout": 0.0}, "/nextage_sim_bridge: parameter 'camera_timeout' must be a number in [0.01, 600] s, got 0"),
        (_simulator, {"speed": 1e-300}, "/nextage_sim_bridge: parameter 'speed' must be a number in [0.01, 1000] x real time, got 1e-300"),
        (_simulator, {"control_period": 1e308}, "/nextage_sim_bridge: parameter 'control_period' must be a number in [0.001, 0.5] s, got 1e+308"),
        (_simulator, {"seed": -1}, "/nextage_sim_bridge: parameter 'seed' must be a whole number in [0, 4294967295], got -1"),
        (_vplus, {"port": 70000}, "/vplus_bridge: parameter 'port' must be a whole number in [0, 65535], got 70000"),
        (_vplus, {"tolerance_mm": 60.0}, "/vplus_bridge: parameter 'tolerance_mm' must be a number in [0.01, 50] mm, got 60"),
        (_vplus, {"tolerance_deg": math.inf}, "/vplus_bridge: parameter 'tolerance_deg' must be a number in [0.01, 10] deg, got inf"),
        (_vplus, {"timeout": 0.0}, "/vplus_bridge: parameter 'timeout' must be a number in [0.1, 600] s, got 0"),
        (_kuka, {"timeout": 0}, "/kuka_rsi_bridge: parameter 'timeout' must be a whole number in [1, 100000], got 0"),
        (_kuka, {"tolerance_mm": 200.0}, "/kuka_rsi_bridge: parameter 'tolerance_mm' must be a number in [0.001, 100] mm, got 200"),
        (_kuka, {"silence": 20.0}, "/kuka_rsi_bridge: parameter 'silence' must be a number in [0.01, 10] s, got 20"),
        (_kuka, {"connect_timeout": math.inf}, "/kuka_rsi_bridge: parameter 'connect_timeout' must be a number in [0.1, 600] s, got inf"),
        (_kuka, {"cycle": 100}, "/kuka_rsi_bridge: parameter 'cycle' must be 4 or 12 ms, got 100"),
        (_kuka, {"cycle": 8}, "/kuka_rsi_bridge: parameter 'cycle' must be 4 or 12 ms, got 8"),  # inside [4, 12], still no RSI cycle
        (_kuka, {"port": -1}, "/kuka_rsi_bridge: parameter 'port' must be a whole number in [0, 65535], got -1"),
    ],
)
def test_a_node_parameter_outside_its_range_is_refused_in_one_line(build: Any, parameters: dict[str, Any], message: str) -> None:
    assert _refusal(build, parameters) == message


def test_a_back_ends_own_range_is_the_one_its_node_takes(run_sim: Any) -> None:
    """KUKA RSI takes a TCP tolerance of 60 mm where V+ refuses it; RSI's silence 0.0 means its default."""
    async def main(clock: Clock) -> tuple[str, str | None]:
        transport = LocalTransport(clock)
        kuka = declare_kuka_parameters(transport.create_node("kuka_rsi_bridge", parameters={"tolerance_mm": 60.0, "silence": 0.0}))
        return kuka.options.extra["tolerance_mm"], kuka.options.extra.get("silence")

    assert run_sim(main) == ("60.0", None)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--timeout", "0"], "argument --timeout: timeout must be a whole number in [1, 100000], got '0'"),
        (["--drop", "2"], "argument --drop: drop must be a number in [0, 1], got '2'"),
        (["--loss", "nan"], "argument --loss: loss must be a number in [0, 1], got 'nan'"),
        (["--jitter-ms", "inf"], "argument --jitter-ms: jitter_ms must be a number in [0, 1000] ms, got 'inf'"),
        (["--cycles", "0"], "argument --cycles: cycles must be a whole number in [1, 1000000000000], got '0'"),
        (["--rt-priority", "200"], "argument --rt-priority: rt_priority must be a whole number in [0, 99], got '200'"),
        (["--reply-grace", "1e308"], "argument --reply-grace: reply_grace must be a number in [0, 60] s, got '1e308'"),
        (["--flood-port", "70000"], "argument --flood-port: port must be a whole number in [0, 65535], got '70000'"),
        (["--axis-monitor", "720"], "argument --axis-monitor: axis_monitor must be a number in [0.001, 360] deg, got '720'"),
    ],
)
def test_the_kr_c4_simulators_numbers_are_refused_outside_their_range(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        kuka_simulator(argv)
    assert stopped.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[-1] == f"python -m robot_bridges.kuka_rsi.simulator: error: {message}"


# --------------------------------------------------------------------------------------- docs
def test_the_docs_show_every_range() -> None:
    """docs/faults.md's table of ranges is table(), row for row, so it cannot drift from the code."""
    text = (ROOT / "docs" / "faults.md").read_text(encoding="utf-8")
    section = text[text.index("## Ranges of numeric settings"):text.index("## The table")]
    documented = re.findall(r"^\| `(\w+)`( \([\w-]+\))? \| ([^|]+) \| ([^|]+) \| ([^|]+) \|$", section, re.MULTILINE)
    assert [(n + scope, r.strip(), w.strip(), x.strip()) for n, scope, r, w, x in documented] == table()
