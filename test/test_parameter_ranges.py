"""Numeric parameters carry their range the ROS way (a descriptor's floating_point_range / integer_range).

What a ROS 2 user relies on: ``ros2 param describe`` prints the Min and Max of a bounded parameter, rclpy refuses a
``ros2 param set`` outside the range (and a declaration whose value lies outside it), and the engine's
``speed_override`` is refused at 150 before the engine sees it.  First the fake rclpy against rclpy's own rules
(:func:`rclpy_behaviour` is written against the rclpy API only; its expected answers are what rclpy 7.1.3 of Jazzy
answered when the same function ran on it), then our nodes through the rclpy transport and the port's rules on the
local transport.  The DDS transport's parameter services: ``test_parameter_ranges_dds.py``.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Coroutine
from types import ModuleType
from typing import Any

import pytest
import ros_fake_parameters
from ros_fake_msgs import FloatingPointRange, IntegerRange, ParameterDescriptor
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from app_functions.registry import full_catalog
from cell_runner.bridge_nodes.kuka_rsi import declare_kuka_parameters
from core_functions.option_ranges import Range, bounds
from execution_engine.engine.engine import ExecutionEngine
from node_transport.bounded import ros_range
from node_transport.clock import Clock, real_clock, run_with_clock, simulated_clock
from node_transport.local import LocalTransport
from node_transport.parameters import NumericRange
from node_transport.port import ParameterChange, TransportError
from node_transport.ros import RosTransport


# =========================================================== the fake rclpy does what rclpy does
def rclpy_behaviour(rclpy: Any, node_class: Any, parameter: Any, descriptor: Any, floating: Any, integer: Any) -> dict[str, str]:
    """Declarations and sets against ranges through the rclpy API; each outcome as text (an exception: its class and message)."""
    rclpy.init(args=["ranges"])
    node = node_class("ranges", parameter_overrides=[parameter("overridden", value=50.0), parameter("cycle_override", value=8)])
    outcomes: dict[str, str] = {}

    def attempt(key: str, action: Callable[[], Any]) -> None:
        try:
            outcomes[key] = repr(action())
        except Exception as error:  # noqa: BLE001 - the exception is the outcome
            outcomes[key] = f"{type(error).__name__}: {error}"

    def percent() -> Any:
        return descriptor(description="percent", floating_point_range=[floating(from_value=0.0, to_value=100.0, step=0.0)])

    def cycle() -> Any:
        return descriptor(integer_range=[integer(from_value=4, to_value=12, step=8)])

    try:
        attempt("declare default outside", lambda: node.declare_parameter("outside", 150.0, percent()).value)
        attempt("declare default outside, override inside", lambda: node.declare_parameter("overridden", 150.0, percent()).value)
        attempt("declare override off the step", lambda: node.declare_parameter("cycle_override", 4, cycle()).value)
        attempt("declare integer for a double range", lambda: node.declare_parameter("int_in_double", 5, percent()).value)
        node.declare_parameter("speed", 100.0, percent())
        node.declare_parameter("cycle", 4, cycle())
        for name, value in (("speed", 150.0), ("speed", -1.0), ("speed", math.nan), ("speed", 100.00005), ("speed", 0.0),
                            ("speed", 50), ("cycle", 8), ("cycle", 12), ("cycle", 13), ("cycle", 4.0)):
            result = node.set_parameters([parameter(name, value=value)])[0]
            outcomes[f"set {name} {value!r}"] = f"{result.successful} {result.reason}"
        node.add_pre_set_parameters_callback(lambda ps: [parameter(p.name, value=float(p.value)) if p.name == "speed" else p for p in ps])
        result = node.set_parameters([parameter("speed", value=50)])[0]
        outcomes["set speed 50 widened by a pre-set callback"] = f"{result.successful} {result.reason} {node.get_parameter('speed').value!r}"
        result = node.set_parameters_atomically([parameter("speed", value=20.0), parameter("cycle", value=8)])
        outcomes["atomic set, one outside"] = f"{result.successful} {result.reason} {node.get_parameter('speed').value!r}"
        described = node.describe_parameter("speed")
        ranged = described.floating_point_range[0]
        outcomes["describe speed"] = repr((described.type, described.description, ranged.from_value, ranged.to_value, ranged.step, list(described.integer_range)))
        described = node.describe_parameter("cycle")
        stepped = described.integer_range[0]
        outcomes["describe cycle"] = repr((described.type, stepped.from_value, stepped.to_value, stepped.step, list(described.floating_point_range)))
    finally:
        node.destroy_node()
        rclpy.shutdown()
    return outcomes


#: What rclpy 7.1.3 (Jazzy, built from source) answered to :func:`rclpy_behaviour`.
RCLPY_7_1_3 = {
    "declare default outside": "InvalidParameterValueException: Invalid parameter value (150.0) for parameter. Reason: "
                               "Parameter outside out of range Min: 0.0, Max: 100.0, value: 150.0: outside",
    "declare default outside, override inside": "50.0",
    "declare override off the step": "InvalidParameterValueException: Invalid parameter value (8) for parameter. Reason: "
                                     "The parameter value for cycle_override is not a valid step. Min: 4, max: 12, value: 8, step: 8: cycle_override",
    "declare integer for a double range": "5",
    "set speed 150.0": "False Parameter speed out of range Min: 0.0, Max: 100.0, value: 150.0",
    "set speed -1.0": "False Parameter speed out of range Min: 0.0, Max: 100.0, value: -1.0",
    "set speed nan": "False Parameter speed out of range Min: 0.0, Max: 100.0, value: nan",
    "set speed 100.00005": "True ",
    "set speed 0.0": "True ",
    "set speed 50": "False Wrong parameter type, expected 'Type.DOUBLE' got 'Type.INTEGER'",
    "set cycle 8": "False The parameter value for cycle is not a valid step. Min: 4, max: 12, value: 8, step: 8",
    "set cycle 12": "True ",
    "set cycle 13": "False Parameter cycle out of range. Min: 4, Max: 12, value: 13",
    "set cycle 4.0": "False Wrong parameter type, expected 'Type.INTEGER' got 'Type.DOUBLE'",
    "set speed 50 widened by a pre-set callback": "True  50.0",
    "atomic set, one outside": "False The parameter value for cycle is not a valid step. Min: 4, max: 12, value: 8, step: 8 50.0",
    "describe speed": "(3, 'percent', 0.0, 100.0, 0.0, [])",
    "describe cycle": "(2, 4, 12, 8, [])",
}


def test_the_fake_rclpy_checks_ranges_as_rclpy_does(fake_rclpy: ModuleType) -> None:
    outcomes = rclpy_behaviour(fake_rclpy, fake_rclpy.node.Node, ros_fake_parameters.Parameter, ParameterDescriptor, FloatingPointRange, IntegerRange)
    assert outcomes == RCLPY_7_1_3


# ================================================================== our nodes through rclpy
def _on_rclpy(body: Callable[[RosTransport], Coroutine[Any, Any, Any]], argv: list[str] | None = None) -> Any:
    async def main(clock: Clock) -> Any:
        transport = RosTransport(clock, argv or ["node"])
        try:
            return await body(transport)
        finally:
            await transport.shutdown()

    return run_with_clock(main, real_clock())


def test_speed_override_shows_its_range_and_rclpy_refuses_150_before_the_engine_sees_it(fake_rclpy: ModuleType) -> None:
    async def body(transport: RosTransport) -> tuple[Any, ...]:
        node = transport.create_node("execution_engine")
        engine = ExecutionEngine(node, full_catalog())
        described = node.ros_node.describe_parameter("speed_override")
        refused = node.ros_node.set_parameters([ros_fake_parameters.Parameter("speed_override", value=150.0)])[0]
        for _ in range(10):
            await transport.clock.sleep(0.01)  # a taken value would reach the engine's loop by now
        percent_after_refusal, changes_after_refusal = engine.speed.percent, list(engine.speed.changes)
        taken = node.ros_node.set_parameters([ros_fake_parameters.Parameter("speed_override", value=50)])[0]  # `ros2 param set ... 50`: an integer
        for _ in range(100):
            if engine.speed.percent == 50.0:
                break
            await transport.clock.sleep(0.01)
        timeout = node.ros_node.describe_parameter("service_timeout").floating_point_range[0]
        return described, refused, percent_after_refusal, changes_after_refusal, taken, engine.speed.percent, (timeout.from_value, timeout.to_value)

    described, refused, percent, changes, taken, later, timeout = _on_rclpy(body)
    ranged = described.floating_point_range[0]
    assert (described.type, ranged.from_value, ranged.to_value, ranged.step, list(described.integer_range)) == (3, 0.0, 100.0, 0.0, [])
    assert "range [0, 100] %" in described.description
    assert not refused.successful and refused.reason == "Parameter speed_override out of range Min: 0.0, Max: 100.0, value: 150.0"
    assert percent == 100.0 and changes == []  # refused by rclpy: nothing reached the engine
    assert taken.successful and later == 50.0
    assert timeout == (0.1, 600.0)


def test_kuka_parameters_integer_ranges_a_stepped_cycle_and_silence_without_a_range(fake_rclpy: ModuleType) -> None:
    async def body(transport: RosTransport) -> dict[str, Any]:
        node = transport.create_node("kuka_rsi_bridge")
        declare_kuka_parameters(node)
        return {name: node.ros_node.describe_parameter(name) for name in ("cycle", "port", "timeout", "tolerance_mm", "silence")}

    described = _on_rclpy(body)

    def integer(name: str) -> tuple[int, int, int]:
        only = described[name].integer_range
        assert len(only) == 1 and described[name].floating_point_range == [] and described[name].type == 2
        return only[0].from_value, only[0].to_value, only[0].step

    assert integer("cycle") == (4, 12, 8)  # 4 or 12 ms, nothing between
    assert integer("port") == (0, 65535, 0)
    assert integer("timeout") == (1, 100000, 0)
    tolerance = described["tolerance_mm"].floating_point_range[0]
    assert (tolerance.from_value, tolerance.to_value) == (0.001, 100.0)
    silence = described["silence"]
    assert silence.floating_point_range == [] and silence.integer_range == []  # 0.0 (its default) lies outside [0.01, 10]
    assert "range [0.01, 10] s (or 0: the back end's default)" in silence.description


@pytest.mark.parametrize(("argv", "message"), [
    (["kuka", "--ros-args", "-p", "cycle:=8"], "/kuka_rsi_bridge: parameter 'cycle' must be 4 or 12 ms, got 8"),
    (["kuka", "--ros-args", "-p", "silence:=20.0"], "/kuka_rsi_bridge: parameter 'silence' must be a number in [0.01, 10] s, got 20"),
])
def test_an_override_outside_the_range_ends_start_up_in_the_projects_words_under_rclpy(fake_rclpy: ModuleType, argv: list[str], message: str) -> None:
    async def body(transport: RosTransport) -> str:
        with pytest.raises(TransportError) as refused:
            declare_kuka_parameters(transport.create_node("kuka_rsi_bridge"))
        return str(refused.value)

    assert _on_rclpy(body, argv) == message


def test_silence_given_zero_or_inside_its_range_starts(fake_rclpy: ModuleType) -> None:
    async def body(transport: RosTransport) -> Any:
        node = transport.create_node("kuka_rsi_bridge")
        setup = declare_kuka_parameters(node)
        return setup.options.extra.get("silence"), node.ros_node.get_parameter("silence").value

    assert _on_rclpy(body, ["kuka", "--ros-args", "-p", "silence:=0.5"]) == ("0.5", 0.5)
    assert _on_rclpy(body, ["kuka", "--ros-args", "-p", "silence:=0"]) == (None, 0.0)  # rcl types 0 as an integer: widened, unset


# ============================================================ the port's rules, any transport
def _local(body: Callable[[LocalTransport], Any]) -> Any:
    async def main(clock: Clock) -> Any:
        return body(LocalTransport(clock))

    return run_with_clock(main, simulated_clock())


def test_a_declaration_outside_its_range_fails_as_rclpy_fails_it() -> None:
    percent = NumericRange(0.0, 100.0)

    def body(transport: LocalTransport) -> tuple[str, Any, Any]:
        with pytest.raises(TransportError) as refused:
            transport.create_node("plain").declare_parameter("share", 150.0, "percent", percent)
        inside = transport.create_node("given", parameters={"share": 50}).declare_parameter("share", 150.0, "percent", percent)
        counted = transport.create_node("counted")
        counted.declare_parameter("count", 4, "", NumericRange(4.0, 12.0, 8.0))
        return str(refused.value), inside, counted.ranges["count"]

    refusal, inside, counted = _local(body)
    assert refusal == "/plain: Parameter share out of range Min: 0.0, Max: 100.0, value: 150.0"
    assert inside == 50.0  # rclpy checks the value declared: the override, not the default
    assert counted == NumericRange(4, 12, 8) and isinstance(counted.from_value, int)  # an integer parameter: an IntegerRange


def test_a_run_time_change_outside_the_range_is_refused_and_changes_nothing() -> None:
    taken: list[Any] = []

    def body(transport: LocalTransport) -> tuple[str, str, str, Any]:
        node = transport.create_node("gain")
        node.declare_parameter("gain", 1.0, "", NumericRange(0.5, 2.0))
        node.changeable_parameter("gain", ParameterChange(lambda value: "", taken.append))  # no check of its own: the range holds
        return node.set_parameter("gain", 3.0), node.set_parameter("gain", 2), node.set_parameter("gain", 0.75), node.get_parameter("gain")

    above, edge, inside, value = _local(body)
    assert above == "Parameter gain out of range Min: 0.5, Max: 2.0, value: 3.0"
    assert edge == inside == "" and taken == [2.0, 0.75] and value == 0.75


def test_a_range_on_a_parameter_that_is_not_a_number_is_a_mistake_of_the_code() -> None:
    def body(transport: LocalTransport) -> None:
        transport.create_node("n").declare_parameter("name", "x", "", NumericRange(0.0, 1.0))

    with pytest.raises(TransportError, match=r"^/n: parameter 'name': a range needs an integer or double parameter, not string 'x'$"):
        _local(body)


@pytest.mark.parametrize(("allowed", "unset", "expected"), [
    (bounds("speed_override"), None, NumericRange(0.0, 100.0, 0.0)),
    (bounds("cycle"), None, NumericRange(4, 12, 8)),  # 4 or 12: a step from one end to the other
    (Range(1, 9, choices=(1, 5, 9)), None, NumericRange(1, 9, 4)),
    (Range(1, 9, choices=(1, 2, 9)), None, None),  # not evenly spaced: no ROS range can say it
    (Range(1, 9, choices=(2, 9)), None, None),  # not from the lower end
    (bounds("silence"), 0.0, None),  # its "unset" 0.0 lies outside [0.01, 10]
    (Range(0.0, 10.0), 0.0, NumericRange(0.0, 10.0, 0.0)),  # an unset value inside the range needs nothing
    (Range(0, 10, integer=True), None, NumericRange(0, 10, 1.0)),  # whole numbers, should it be declared as a double
])
def test_which_settings_a_ros_range_can_carry(allowed: Range, unset: float | None, expected: NumericRange | None) -> None:
    assert ros_range(allowed, unset) == expected
