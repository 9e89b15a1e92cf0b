"""The rclpy adapter, driven through a fake rclpy (test/ros_fakes.py) with a real executor thread.

These tests run on a real-time loop, because the executor thread is real: every wait is for an
event a callback sets, bounded by a generous timeout that only turns a hang into a failure.
"""
from __future__ import annotations

import asyncio
import sys
import threading
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import pytest
import ros_fake_callbacks
import ros_fake_context
import ros_fake_msgs
import ros_fake_parameters
import ros_fake_qos
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.msgs import Bool, Header, JointState, String, Time, Trigger, TriggerRequest, TriggerResponse
from node_transport.port import ServiceUnavailable, TransportError, wait_until_matched
from node_transport.qos import COMMANDS, LATCHED, SENSOR
from node_transport.ros import RosTransport

T = TypeVar("T")
BOUND = 5.0  # s: only ever reached when something hangs


def run_real(main: Callable[[Clock], Coroutine[Any, Any, T]]) -> T:
    return run_with_clock(main, real_clock())


class Inbox:
    """Collects callback arguments on the loop and wakes a waiter when enough arrived."""

    def __init__(self) -> None:
        self.items: list[Any] = []
        self.threads: set[int] = set()
        self._changed = asyncio.Event()

    def __call__(self, *item: Any) -> None:
        self.items.append(item[0] if len(item) == 1 else item)
        self.threads.add(threading.get_ident())
        self._changed.set()

    async def wait(self, clock: Clock, count: int = 1) -> list[Any]:
        while len(self.items) < count:
            self._changed.clear()
            await clock.wait_for(self._changed.wait(), BOUND)
        return self.items


async def matched(transport: RosTransport, *endpoints: Any) -> None:
    """What every real caller does before the first message: wait for DDS discovery."""
    assert await wait_until_matched(transport.clock, endpoints, BOUND)


async def raw_matched(clock: Clock, count: Callable[[], int]) -> None:
    deadline = clock.now() + BOUND
    while count() == 0:
        assert clock.now() < deadline, "never matched"
        await clock.sleep(0.005)


async def with_transport(clock: Clock, body: Callable[[RosTransport], Coroutine[Any, Any, T]], **kwargs: Any) -> T:
    transport = RosTransport(clock, ["test"], **kwargs)
    try:
        return await body(transport)
    finally:
        await transport.shutdown()


# ======================================================================================= topics
def test_messages_cross_nodes_converted_and_delivered_on_the_loop_thread(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        talker, listener = transport.create_node("talker"), transport.create_node("listener")
        inbox = Inbox()
        sub = listener.create_subscription(JointState, "/joint_states", inbox, SENSOR)
        sent = JointState(Header(Time(3, 250), "WAIST"), ("CHEST_JOINT0",), (0.25,))
        pub = talker.create_publisher(JointState, "/joint_states", SENSOR)
        await matched(transport, pub, sub)
        pub.publish(sent)
        assert await inbox.wait(transport.clock) == [sent]
        assert inbox.threads == {threading.get_ident()}  # the loop's thread, not an executor thread
        executor = listener.ros_node.executor
        assert threading.get_ident() not in executor.callback_threads

    run_real(lambda clock: with_transport(clock, body))


def test_a_topic_keeps_its_order_across_executor_threads(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        a, b = transport.create_node("a"), transport.create_node("b")
        inbox = Inbox()
        sub = b.create_subscription(String, "/events", lambda m: inbox(m.data), COMMANDS)
        # rclpy runs a reentrant entity's callbacks concurrently; only an exclusive group keeps order.
        assert isinstance(sub.handle.callback_group, ros_fake_callbacks.MutuallyExclusiveCallbackGroup)  # type: ignore[attr-defined]
        pub = a.create_publisher(String, "/events", COMMANDS)
        await matched(transport, pub, sub)
        for i in range(40):
            pub.publish(String(str(i)))
        assert await inbox.wait(transport.clock, 40) == [str(i) for i in range(40)]

    run_real(lambda clock: with_transport(clock, body, threads=4))


def test_qos_reaches_rclpy_and_latched_state_reaches_a_late_subscriber(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        machine = transport.create_node("machine")
        pub = machine.create_publisher(String, "/left_arm/sm/state", LATCHED)
        pub.publish(String("Ready"))
        rclpy_pub = pub.handle  # type: ignore[attr-defined]
        assert rclpy_pub.qos.durability is ros_fake_qos.DurabilityPolicy.TRANSIENT_LOCAL and rclpy_pub.qos.depth == 1
        inbox = Inbox()
        transport.create_node("viewer").create_subscription(String, "/left_arm/sm/state", inbox, LATCHED)
        assert await inbox.wait(transport.clock) == [String("Ready")]

    run_real(lambda clock: with_transport(clock, body))


def test_a_failing_callback_is_reported_and_later_messages_still_arrive(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        a, b = transport.create_node("a"), transport.create_node("b")
        faults = Inbox()
        b.fault_handler = faults
        inbox = Inbox()

        def callback(msg: Bool) -> None:
            if not msg.data:
                raise ValueError("false is not allowed")
            inbox(msg)

        b.create_subscription(Bool, "/cell/safety_stop", callback, COMMANDS)
        pub = a.create_publisher(Bool, "/cell/safety_stop", COMMANDS)
        await matched(transport, pub)
        pub.publish(Bool(False))
        pub.publish(Bool(True))
        assert await inbox.wait(transport.clock) == [Bool(True)]
        where, error = (await faults.wait(transport.clock))[0]
        assert where == "subscription /cell/safety_stop" and isinstance(error, ValueError)
        assert faults.threads == {threading.get_ident()}
        assert transport.spin_error is None and transport._thread.is_alive()

    run_real(lambda clock: with_transport(clock, body))


def test_a_message_that_cannot_be_converted_is_reported_not_delivered(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        node = transport.create_node("listener")
        faults, inbox = Inbox(), Inbox()
        node.fault_handler = faults
        node.create_subscription(JointState, "/joint_states", inbox, SENSOR)
        garbled = ros_fake_msgs.JointState(name=["a"])
        object.__setattr__(garbled, "_name", [7])  # what a mis-typed peer could deliver
        raw = node.ros_node.create_publisher(ros_fake_msgs.JointState, "/joint_states", ros_fake_qos.QoSProfile(depth=5))
        await raw_matched(transport.clock, raw.get_subscription_count)
        raw.publish(garbled)
        raw.publish(ros_fake_msgs.JointState(name=["b"]))
        assert [m.name for m in await inbox.wait(transport.clock)] == [("b",)]
        where, error = faults.items[0]
        assert where == "subscription /joint_states" and isinstance(error, TransportError) and "name[0]" in str(error)

    run_real(lambda clock: with_transport(clock, body))


# ===================================================================================== services
def test_a_service_call_runs_the_handler_on_the_loop_and_converts_both_ways(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        server, caller = transport.create_node("machine"), transport.create_node("engine")
        threads: list[int] = []

        async def pause(request: TriggerRequest) -> TriggerResponse:
            threads.append(threading.get_ident())
            await transport.clock.sleep(0)
            return TriggerResponse(True, "left_arm: pause accepted in Ready")

        server.create_service(Trigger, "/left_arm/sm/pause", pause)
        client = caller.create_client(Trigger, "/left_arm/sm/pause")
        assert await client.wait_for_service(BOUND)
        assert await client.call(TriggerRequest(), timeout=BOUND) == TriggerResponse(True, "left_arm: pause accepted in Ready")
        assert threads == [threading.get_ident()]
        with pytest.raises(TransportError, match="takes TriggerRequest, got String"):
            await client.call(String("pause"), timeout=BOUND)

    run_real(lambda clock: with_transport(clock, body))


def test_a_handler_that_calls_another_service_does_not_starve_its_own_answer(fake_rclpy: Any) -> None:
    # The engine's pause service calls each machine's pause service: the executor must take the
    # machine's response while a thread waits in the engine's handler.
    async def body(transport: RosTransport) -> None:
        engine, machine, operator = (transport.create_node(n) for n in ("engine", "machine", "operator"))

        async def machine_pause(request: TriggerRequest) -> TriggerResponse:
            return TriggerResponse(True, "machine paused")

        served = machine.create_service(Trigger, "/left_arm/sm/pause", machine_pause)
        to_machine = engine.create_client(Trigger, "/left_arm/sm/pause")
        # The client's responses are taken while a thread waits in a handler: a reentrant group.
        assert isinstance(to_machine.handle.callback_group, ros_fake_callbacks.ReentrantCallbackGroup)  # type: ignore[attr-defined]
        # Each service its own exclusive group: it can be destroyed between requests (see ros.py).
        assert isinstance(served.handle.callback_group, ros_fake_callbacks.MutuallyExclusiveCallbackGroup)  # type: ignore[attr-defined]

        async def engine_pause(request: TriggerRequest) -> TriggerResponse:
            answer = await to_machine.call(TriggerRequest(), timeout=BOUND)
            return TriggerResponse(answer.success, f"engine: {answer.message}")

        engine.create_service(Trigger, "/execution_engine/pause", engine_pause)
        response = await operator.create_client(Trigger, "/execution_engine/pause").call(TriggerRequest(), timeout=BOUND)
        assert response == TriggerResponse(True, "engine: machine paused")

    run_real(lambda clock: with_transport(clock, body, threads=2))


def test_a_failing_handler_answers_failure_and_reports_the_fault(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        server, caller = transport.create_node("machine"), transport.create_node("engine")
        faults = Inbox()
        server.fault_handler = faults

        async def broken(request: TriggerRequest) -> TriggerResponse:
            raise RuntimeError("state table corrupt")

        async def wrong(request: TriggerRequest) -> Any:
            return "ok"

        server.create_service(Trigger, "/left_arm/sm/reset", broken)
        server.create_service(Trigger, "/left_arm/sm/stop", wrong)
        response = await caller.create_client(Trigger, "/left_arm/sm/reset").call(TriggerRequest(), timeout=BOUND)
        assert response == TriggerResponse(False, "/left_arm/sm/reset: RuntimeError: state table corrupt")
        response = await caller.create_client(Trigger, "/left_arm/sm/stop").call(TriggerRequest(), timeout=BOUND)
        assert not response.success and "answered str" in response.message
        await faults.wait(transport.clock, 2)
        assert [w for w, _ in faults.items] == ["service /left_arm/sm/reset", "service /left_arm/sm/stop"]
        assert transport.spin_error is None

    run_real(lambda clock: with_transport(clock, body))


def test_a_handler_that_never_answers_is_cut_off_and_cancelled(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        server, caller = transport.create_node("machine"), transport.create_node("engine")
        faults, cancelled = Inbox(), Inbox()
        server.fault_handler = faults

        async def stuck(request: TriggerRequest) -> TriggerResponse:
            try:
                await asyncio.Event().wait()
            except asyncio.CancelledError:
                cancelled(True)
                raise
            raise AssertionError("unreachable")

        server.create_service(Trigger, "/left_arm/sm/stop", stuck)
        response = await caller.create_client(Trigger, "/left_arm/sm/stop").call(TriggerRequest(), timeout=BOUND)
        assert not response.success and "TimeoutError: handler did not answer within 0.2 s" in response.message
        assert await cancelled.wait(transport.clock) == [True]
        assert isinstance((await faults.wait(transport.clock))[0][1], TimeoutError)

    run_real(lambda clock: with_transport(clock, body, handler_timeout=0.2))


def test_calls_without_a_server_or_without_an_answer_fail_in_time(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        server, caller = transport.create_node("machine"), transport.create_node("engine")
        client = caller.create_client(Trigger, "/left_arm/sm/resume")
        assert not await client.wait_for_service(0.1)
        with pytest.raises(ServiceUnavailable, match="no server for service /left_arm/sm/resume within 0.1 s"):
            await client.call(TriggerRequest(), timeout=0.1)
        release = asyncio.Event()

        async def slow(request: TriggerRequest) -> TriggerResponse:
            await release.wait()
            return TriggerResponse(True, "late")

        server.create_service(Trigger, "/left_arm/sm/resume", slow)
        assert await client.wait_for_service(BOUND)
        with pytest.raises(TimeoutError, match="did not answer within 0.1 s"):
            await client.call(TriggerRequest(), timeout=0.1)
        assert len(client.handle.removed) == 1  # type: ignore[attr-defined]  # rclpy forgets the request
        release.set()

    run_real(lambda clock: with_transport(clock, body))


# =================================================================================== parameters
def test_parameters_come_from_ros_arguments_and_code_and_are_read_once(fake_rclpy: Any) -> None:
    argv = ["nextage_sim_bridge", "--ros-args", "-p", "speed:=2", "-p", "sped:=3.0", "-r", "__node:=sim_bridge", "--", "extra"]

    async def main(clock: Clock) -> None:
        transport = RosTransport(clock, argv)
        try:
            assert transport.user_args(argv) == ["extra"]
            node = transport.create_node("nextage_sim_bridge", parameters={"seed": 7})
            assert node.name == "sim_bridge" and node.fully_qualified_name == "/sim_bridge"
            assert node.declare_parameter("speed", 1.0, "simulation speed") == 2.0
            assert node.declare_parameter("seed", 0) == 7
            assert node.declare_parameter("state_period", 0.05, "publish period") == 0.05
            assert node.undeclared_overrides() == ["sped"]
            assert node.ros_node.get_parameter("state_period").value == 0.05
            assert node.ros_node.describe_parameter("state_period").description == "publish period"  # ros2 param describe
            refused = node.ros_node.set_parameters([ros_fake_parameters.Parameter("speed", value=5.0)])[0]
            assert not refused.successful and "read at start-up" in refused.reason
            with pytest.raises(TransportError, match="parameter 'sped' must be true or false, got double 3.0"):
                node.declare_parameter("sped", True)
        finally:
            await transport.shutdown()

    run_real(main)
    assert ros_fake_context.CONTEXT.init_kwargs["signal_handler_options"] is ros_fake_context.SignalHandlerOptions.NO


# ===================================================================================== lifecycle
def test_shutdown_stops_the_executor_destroys_nodes_and_rclpy(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, Any]:
        transport = RosTransport(clock, ["test"])
        node = transport.create_node("engine")
        with pytest.raises(TransportError, match="already exists"):
            transport.create_node("engine")
        await transport.shutdown()
        await clock.wait_for(transport.wait_closed(), BOUND)
        with pytest.raises(TransportError, match="shut down"):
            transport.create_node("late")
        return transport, node

    transport, node = run_real(main)
    assert not transport._thread.is_alive()
    assert node.ros_node.destroyed
    assert not ros_fake_context.CONTEXT.ok() and ros_fake_context.CONTEXT.shutdown_count == 1


def test_rclpy_initialised_by_someone_else_is_left_running(fake_rclpy: Any) -> None:
    fake_rclpy.init(args=["host"])

    async def main(clock: Clock) -> None:
        transport = RosTransport(clock, ["test"])
        transport.create_node("engine")
        await transport.shutdown()

    run_real(main)
    assert ros_fake_context.CONTEXT.ok() and ros_fake_context.CONTEXT.init_count == 1
    fake_rclpy.shutdown()


def test_shutdown_is_not_held_up_by_a_handler_in_flight(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> str:
        transport = RosTransport(clock, ["test"], handler_timeout=60.0)
        server, caller = transport.create_node("machine"), transport.create_node("engine")
        entered = Inbox()

        async def stuck(request: TriggerRequest) -> TriggerResponse:
            entered(True)
            await asyncio.Event().wait()
            raise AssertionError("unreachable")

        server.create_service(Trigger, "/left_arm/sm/stop", stuck)
        call = asyncio.ensure_future(caller.create_client(Trigger, "/left_arm/sm/stop").call(TriggerRequest(), timeout=60.0))
        await entered.wait(clock)
        await clock.wait_for(transport.shutdown(), BOUND)
        with pytest.raises(TransportError, match="destroyed during the call"):
            await call
        return "stopped"

    assert run_real(main) == "stopped"


def test_rclpy_shut_down_from_outside_wakes_the_loop(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> None:
        transport = RosTransport(clock, ["test"])
        try:
            transport.create_node("engine")
            threading.Thread(target=fake_rclpy.shutdown).start()
            await clock.wait_for(transport.wait_closed(), BOUND)
            assert transport.spin_error is None
        finally:
            await transport.shutdown()

    run_real(main)


def test_a_destroyed_node_neither_publishes_nor_receives(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> None:
        a, b = transport.create_node("a"), transport.create_node("b")
        inbox = Inbox()
        b.create_subscription(String, "/x", inbox, COMMANDS)
        pub_a = a.create_publisher(String, "/x", COMMANDS)
        pub_b = b.create_publisher(String, "/x", COMMANDS)
        await matched(transport, pub_a, pub_b)
        assert pub_a.get_subscription_count() == 1
        b.destroy()
        assert pub_b.get_subscription_count() == 0 and pub_a.get_subscription_count() == 0  # b left the graph
        with pytest.raises(TransportError, match="was destroyed"):
            pub_b.publish(String("from b"))
        pub_a.publish(String("to b"))
        probe = Inbox()
        probe_sub = transport.create_node("c").create_subscription(String, "/x", probe, COMMANDS)
        await matched(transport, probe_sub)
        pub_a.publish(String("to c"))
        await probe.wait(transport.clock)  # delivered after "to b" on the same executor
        assert inbox.items == [] and transport.node_names() == ["/a", "/c"]

    run_real(lambda clock: with_transport(clock, body))


def test_simulated_time_is_refused(fake_rclpy: Any, run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        with pytest.raises(ValueError, match="runs in wall time"):
            RosTransport(clock)

    run_sim(main)


def test_without_rclpy_the_error_says_how_to_get_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rclpy", None)

    async def main(clock: Clock) -> None:
        with pytest.raises(TransportError, match="source a ROS 2 Jazzy environment"):
            RosTransport(clock)

    run_real(main)
