"""The in-process transport keeps the ROS 2 semantics the nodes rely on."""
from __future__ import annotations

from typing import Any

import pytest

from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import Bool, String, Trigger
from node_transport.port import ServiceUnavailable, TransportError, resolve_name
from node_transport.qos import COMMANDS, LATCHED, SENSOR, Durability, History, QoS, Reliability, rclpy_qos_kwargs


def test_delivery_is_asynchronous_and_in_order(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[str], list[str]]:
        bus = LocalTransport(clock)
        a, b = bus.create_node("a"), bus.create_node("b")
        got: list[str] = []
        b.create_subscription(String, "/chatter", lambda m: got.append(m.data))
        pub = a.create_publisher(String, "/chatter")
        for i in range(5):
            pub.publish(String(str(i)))
        during = list(got)  # nothing is delivered inside publish
        await clock.sleep(0)
        return during, got

    during, got = run_sim(main)
    assert during == [] and got == ["0", "1", "2", "3", "4"]


def test_keep_last_drops_the_oldest(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[str]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        got: list[str] = []
        node.create_subscription(String, "/t", lambda m: got.append(m.data), QoS(depth=2))
        pub = node.create_publisher(String, "/t", QoS(depth=2))
        for i in range(5):
            pub.publish(String(str(i)))
        await clock.sleep(0)
        return got

    assert run_sim(main) == ["3", "4"]


def test_transient_local_reaches_late_subscribers_and_volatile_does_not(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[str], list[str]]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        node.create_publisher(String, "/latched", LATCHED).publish(String("state"))
        node.create_publisher(String, "/volatile", COMMANDS).publish(String("lost"))
        latched: list[str] = []
        volatile: list[str] = []
        node.create_subscription(String, "/latched", lambda m: latched.append(m.data), LATCHED)
        node.create_subscription(String, "/volatile", lambda m: volatile.append(m.data), COMMANDS)
        await clock.sleep(0)
        return latched, volatile

    assert run_sim(main) == (["state"], [])


def test_incompatible_qos_does_not_connect(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[str]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        got: list[str] = []
        node.create_subscription(String, "/s", lambda m: got.append(m.data), COMMANDS)  # wants reliable
        node.create_publisher(String, "/s", SENSOR).publish(String("best effort"))  # offers best effort
        await clock.sleep(0)
        return got

    assert run_sim(main) == []
    assert not COMMANDS.compatible_with(SENSOR) and SENSOR.compatible_with(COMMANDS)


def test_types_are_enforced_per_topic(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        pub = node.create_publisher(String, "/typed")
        with pytest.raises(TransportError, match="carries String, got Bool"):
            pub.publish(Bool(True))  # type: ignore[arg-type]
        with pytest.raises(TransportError, match="topic /typed carries String"):
            node.create_subscription(Bool, "/typed", lambda m: None)

    run_sim(main)


def test_a_failing_callback_is_reported_to_the_node_and_delivery_goes_on(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[str], list[str]]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        faults: list[str] = []
        node.fault_handler = lambda where, error: faults.append(f"{where}: {error}")
        got: list[str] = []

        def callback(msg: String) -> None:
            if msg.data == "bad":
                raise ValueError("cannot parse")
            got.append(msg.data)

        node.create_subscription(String, "/in", callback)
        pub = node.create_publisher(String, "/in")
        for text in ("a", "bad", "b"):
            pub.publish(String(text))
        await clock.sleep(0)
        return got, faults

    got, faults = run_sim(main)
    assert got == ["a", "b"] and faults == ["subscription /in: cannot parse"]


def test_services_call_wait_and_time_out(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        bus = LocalTransport(clock)
        server, client_node = bus.create_node("server"), bus.create_node("client")
        client = client_node.create_client(Trigger, "/do")
        assert not await client.wait_for_service(1.0)
        with pytest.raises(ServiceUnavailable, match="no server for service /do"):
            await client.call(Trigger.Request())

        async def slow(request: Any) -> Any:
            await clock.sleep(10.0)
            return Trigger.Response(True, "done")

        server.create_service(Trigger, "/do", slow)
        assert await client.wait_for_service(1.0)
        with pytest.raises(TimeoutError):
            await client.call(Trigger.Request(), timeout=2.0)
        assert (await client.call(Trigger.Request(), timeout=20.0)).message == "done"
        with pytest.raises(TransportError, match="already served"):
            client_node.create_service(Trigger, "/do", slow)

    run_sim(main)


def test_node_names_parameters_and_destroy(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        bus = LocalTransport(clock)
        node = bus.create_node("machine", namespace="/cell1", parameters={"group": "right_arm", "speed": 2, "typo": 1})
        assert node.declare_parameter("group", "left_arm") == "right_arm"
        assert node.declare_parameter("speed", 1.0) == 2.0  # an int override of a float parameter is fine
        assert node.declare_parameter("missing", 5) == 5
        assert node.undeclared_overrides() == ["typo"]
        with pytest.raises(TransportError, match="must be true or false, got string"):
            bus.create_node("other", parameters={"flag": "yes"}).declare_parameter("flag", True)
        with pytest.raises(TransportError, match="declared twice"):
            node.declare_parameter("group", "x")
        with pytest.raises(TransportError, match="already exists"):
            bus.create_node("machine", namespace="/cell1")
        assert node.resolve("status") == "/cell1/status" and node.resolve("~/state") == "/cell1/machine/state"
        got: list[str] = []
        node.create_subscription(String, "/x", lambda m: got.append(m.data))
        node.destroy()
        bus.create_node("p").create_publisher(String, "/x").publish(String("after destroy"))
        await clock.sleep(0)
        assert got == []
        with pytest.raises(TransportError, match="invalid node name"):
            bus.create_node("bad name")

    run_sim(main)


@pytest.mark.parametrize("name", ["", "/", "//a", "/a/", "/1abc", "/a b", "/a/-b"])
def test_invalid_topic_names_are_refused(name: str) -> None:
    with pytest.raises(TransportError):
        resolve_name(name)


def test_qos_mapping_for_rclpy_is_by_enum_member_name() -> None:
    assert rclpy_qos_kwargs(LATCHED) == {"reliability": "RELIABLE", "durability": "TRANSIENT_LOCAL", "history": "KEEP_LAST", "depth": 1}
    assert rclpy_qos_kwargs(SENSOR)["reliability"] == "BEST_EFFORT"
    with pytest.raises(ValueError, match="depth"):
        QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 0)


def test_a_publisher_reaches_exactly_the_subscriptions_alive_when_it_publishes(run_sim: Any) -> None:
    """Who a publisher reaches is worked out once per graph change, so it must follow every change:
    a subscription made between two messages gets the second, a destroyed one nothing more, and an
    incompatible QoS never matches."""

    async def main(clock: Clock) -> tuple[list[str], list[str], list[str], list[int]]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        pub = node.create_publisher(String, "/t", SENSOR)
        first: list[str] = []
        later: list[str] = []
        strict: list[str] = []
        counts = []
        sub = node.create_subscription(String, "/t", lambda m: first.append(m.data), SENSOR)
        node.create_subscription(String, "/t", lambda m: strict.append(m.data), QoS(reliability=Reliability.RELIABLE))
        counts.append(pub.get_subscription_count())
        pub.publish(String("a"))
        node.create_subscription(String, "/t", lambda m: later.append(m.data), SENSOR)
        counts.append(pub.get_subscription_count())
        pub.publish(String("b"))
        await clock.sleep(0)
        sub.destroy()
        counts.append(pub.get_subscription_count())
        pub.publish(String("c"))
        await clock.sleep(0)
        return first, later, strict, counts

    first, later, strict, counts = run_sim(main)
    assert first == ["a", "b"] and later == ["b", "c"] and strict == [] and counts == [1, 2, 1]
