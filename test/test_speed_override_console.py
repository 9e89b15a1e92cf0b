"""The speed override at the terminal of ``run --interactive``: + and - step it, % asks for a value; the engine
takes each (never above 100 %) and records the key as its source; a value that is no percentage changes nothing."""
from __future__ import annotations

import io
from typing import Any

from cell_runner.deployment import deploy_local
from cell_runner.operator_console import SPEED_STEP, KeyDecoder, OperatorConsole
from core_functions.robots import NEXTAGE_OPEN
from node_transport.clock import Clock, run_with_clock, simulated_clock
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend


def test_plus_minus_and_a_typed_value_set_the_engines_override_and_name_the_key() -> None:
    async def main(clock: Clock) -> tuple[list[str], list[Any], float, float]:
        backend = await create_backend("nextage-sim", clock, BackendOptions(NEXTAGE_OPEN))
        deployment = await deploy_local(clock, NEXTAGE_OPEN, backend)
        try:
            engine = deployment.engine
            screen = io.StringIO()
            console = OperatorConsole(deployment.transport.create_node("operator_console"), screen, engine.operator_command, None, engine.speed)
            for line in ("+", "-", "-", "%", "25", "% 0", "+", "% fast", "% 150"):
                await console.handle_line(line)
            await clock.sleep(0.1)  # the bridge takes the engine's status
            return screen.getvalue().splitlines(), list(engine.speed.changes), engine.speed.percent, backend.speed_override
        finally:
            await deployment.close()

    lines, changes, percent, rate = run_with_clock(main, simulated_clock())
    assert SPEED_STEP == 10.0
    assert lines[0] == "speed: ok - speed override 100 % (was 100 %)"  # + at 100 %: never above the application's speed
    assert lines[1:3] == ["speed: ok - speed override 90 % (was 100 %)", "speed: ok - speed override 80 % (was 90 %)"]
    assert lines[3].startswith("speed override in percent") and lines[4] == "speed: ok - speed override 25 % (was 80 %)"
    assert lines[5] == "speed: ok - speed override 0 % (was 25 %); holding on the path"
    assert lines[6] == "speed: ok - speed override 10 % (was 0 %)"
    assert lines[7] == "speed: refused - 'fast' is no percentage; type 0 to 100, then Enter"
    assert lines[8] == "speed: refused - parameter 'speed_override' must be a number in [0, 100] %, got 150"
    assert [c.source for c in changes] == [f"terminal console (key {k!r})" for k in ("+", "-", "-", "%", "%", "+")]
    assert percent == 10.0 and rate == 0.1


def test_at_a_terminal_the_speed_keys_act_alone_and_percent_reads_a_line() -> None:
    decoder = KeyDecoder(True, frozenset({"g", "%"}))
    assert decoder.feed(b"+-%37.5\r+") == ["+", "-", "%", "37.5", "+"]


def test_without_an_engine_in_the_process_the_console_says_how_to_set_the_parameter() -> None:
    async def main(clock: Clock) -> str:
        backend = await create_backend("nextage-sim", clock, BackendOptions(NEXTAGE_OPEN))
        deployment = await deploy_local(clock, NEXTAGE_OPEN, backend)
        try:
            screen = io.StringIO()
            await OperatorConsole(deployment.transport.create_node("operator_console"), screen).handle_line("+")
            return screen.getvalue()
        finally:
            await deployment.close()

    assert "ros2 param set /execution_engine speed_override" in run_with_clock(main, simulated_clock())
