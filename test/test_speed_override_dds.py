"""The engine's speed_override parameter over the DDS transport: another participant sets it through the rcl parameter
service ``/execution_engine/set_parameters`` (what ``ros2 param set`` calls) and reads it back through
``get_parameters``; the engine takes it as any change (recorded with the parameter as its source); a value out of
range and a parameter read at start-up are refused with the reason in the result."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from dds_domain import domain_env

from app_functions.registry import full_catalog
from execution_engine.engine.engine import ExecutionEngine
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.dds_parameters import GetParameters, SetParameters, message_of, value_of
from node_transport import mirrors
from node_transport.port import poll_until

Parameter = mirrors.mirror("rcl_interfaces/msg/Parameter")
BOUND = 10.0


@pytest.fixture(scope="module")
def env() -> Iterator[dict[str, str]]:
    with domain_env() as claimed:
        yield claimed


def test_ros2_param_set_and_get_reach_the_engines_override_over_dds(env: dict[str, str]) -> None:
    async def main(clock: Clock) -> tuple[Any, ...]:
        cell, tool = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        try:
            engine = ExecutionEngine(cell.create_node("execution_engine"), full_catalog())
            operator = tool.create_node("ros2cli")
            setter = operator.create_client(SetParameters, "/execution_engine/set_parameters")
            getter = operator.create_client(GetParameters, "/execution_engine/get_parameters")

            async def set_(name: str, value: Any) -> Any:
                request = SetParameters.Request(parameters=(Parameter(name=name, value=message_of(value)),))
                return (await setter.call(request, timeout=BOUND)).results[0]

            taken = await set_("speed_override", 50)  # ros2 param set types an unquoted 50 as an integer
            assert await poll_until(clock, lambda: engine.speed.percent == 50.0, BOUND, 0.01)
            read = await getter.call(GetParameters.Request(names=("speed_override", "service_timeout", "nothing")), timeout=BOUND)
            refused = await set_("speed_override", 150.0)
            frozen = await set_("service_timeout", 1.0)
            unknown = await set_("sped_override", 50.0)
            return taken, [value_of(v) for v in read.values], refused, frozen, unknown, engine.speed.percent, engine.speed.changes
        finally:
            await cell.shutdown()
            await tool.shutdown()

    taken, values, refused, frozen, unknown, percent, changes = run_with_clock(main, real_clock())
    assert taken.successful and values == [50.0, 5.0, None]
    assert not refused.successful and refused.reason == "parameter 'speed_override' must be a number in [0, 100] %, got 150"
    assert not frozen.successful and "read at start-up" in frozen.reason
    assert not unknown.successful and "not declared" in unknown.reason
    assert percent == 50.0 and [c.source for c in changes] == ["parameter /execution_engine/speed_override"]
