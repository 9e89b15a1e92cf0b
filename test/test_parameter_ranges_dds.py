"""The ranges of an engine on the DDS transport, through the rcl parameter services another participant calls
(what ``ros2 param describe`` and ``ros2 param set`` call): ``describe_parameters`` returns each numeric
parameter's descriptor with its range in ``floating_point_range`` (what ``ros2 param describe`` prints as Min and
Max), and ``set_parameters`` outside the range is refused with a reason naming it while the override stays."""
from __future__ import annotations

from typing import Any

from dds_domain import domain_env

from app_functions.registry import full_catalog
from execution_engine.engine.engine import ExecutionEngine
from node_transport import mirrors
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.dds_parameters import DescribeParameters, SetParameters, SetParametersAtomically, message_of
from node_transport.port import poll_until

ParameterMsg = mirrors.mirror("rcl_interfaces/msg/Parameter")
WAIT = 10.0  # s: a bound on each call, never reached when the services answer


async def ros2_param(clock: Clock, env: dict[str, str]) -> tuple[Any, ...]:
    """An engine on DDS and, in another participant, the calls ``ros2 param describe`` and ``ros2 param set`` make."""
    engine_side, ros2cli_side = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
    try:
        engine = ExecutionEngine(engine_side.create_node("execution_engine"), full_catalog())
        client = ros2cli_side.create_node("param_client")
        services = {kind: client.create_client(kind, f"/execution_engine/{name}") for kind, name in (
            (DescribeParameters, "describe_parameters"), (SetParameters, "set_parameters"), (SetParametersAtomically, "set_parameters_atomically"))}

        async def speed(value: Any) -> Any:
            one = ParameterMsg(name="speed_override", value=message_of(value))
            return (await services[SetParameters].call(SetParameters.Request(parameters=(one,)), timeout=WAIT)).results[0]

        names = ("speed_override", "startup_timeout", "autostart")
        described = await services[DescribeParameters].call(DescribeParameters.Request(names=names), timeout=WAIT)
        above, below = await speed(150.0), await speed(-5.0)
        unchanged, recorded = engine.speed.percent, [c.percent for c in engine.speed.changes]
        pair = (ParameterMsg(name="speed_override", value=message_of(40.0)), ParameterMsg(name="startup_timeout", value=message_of(1e9)))
        both = (await services[SetParametersAtomically].call(SetParametersAtomically.Request(parameters=pair), timeout=WAIT)).result
        after_atomic = engine.speed.percent
        edge = await speed(0)  # `ros2 param set ... 0`: an integer, at the range's lower end
        assert await poll_until(clock, lambda: engine.speed.percent == 0.0, WAIT, 0.01)
        return described.descriptors, above, below, unchanged, recorded, (both, after_atomic), edge, engine.speed.percent
    finally:
        await engine_side.shutdown()
        await ros2cli_side.shutdown()


def test_describe_shows_the_range_and_set_outside_it_is_refused_over_dds() -> None:
    with domain_env() as env:
        outcome = run_with_clock(lambda clock: ros2_param(clock, env), real_clock())
    descriptors, above, below, unchanged, recorded, both, edge, percent = outcome
    override, startup, autostart = descriptors
    assert [(r.from_value, r.to_value, r.step) for r in override.floating_point_range] == [(0.0, 100.0, 0.0)]
    assert override.type == 3 and override.integer_range == () and not override.read_only and "range [0, 100] %" in override.description
    assert [(r.from_value, r.to_value, r.step) for r in startup.floating_point_range] == [(0.1, 3600.0, 0.0)] and startup.read_only
    assert autostart.type == 1 and autostart.floating_point_range == () and autostart.integer_range == ()  # a bool has none
    assert not above.successful and above.reason == "parameter 'speed_override' must be a number in [0, 100] %, got 150"
    assert not below.successful and below.reason == "parameter 'speed_override' must be a number in [0, 100] %, got -5"
    assert unchanged == 100.0 and recorded == []  # nothing reached the engine's override
    assert not both[0].successful and "startup_timeout read at start-up" in both[0].reason and both[1] == 100.0  # atomic: all or nothing
    assert edge.successful and percent == 0.0
