"""Hand-over subscriptions of the in-process transport (issue 22 item 3): a receiver that only hands a
message on to its node is called inside ``publish``, without a turn of the loop, and nothing else
about delivery changes -- per-subscription order, KEEP_LAST, latched replays, faults reported to the
receiving node, no receiver running inside its own callback."""
from __future__ import annotations

import asyncio
import re
from pathlib import Path
from typing import Any, ClassVar

from app_builder import make_app

from cell_runner.deployment import deploy_local
from cell_runner.libraries import APPLICATION_FUNCTIONS
from core_functions.catalog import Catalog, ParamSpec, ParamType, skill
from core_functions.functions import CoreFunctions, Skill
from core_functions.primitives import SetSpeed
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model.application import load_application
from execution_engine.function_library import FunctionLibrary
from node_transport import typed
from node_transport.carriage import TypedPublisher, subscribe
from node_transport.clock import Clock, run_with_clock, simulated_clock
from node_transport.local import HAND_OVER_DEPTH, LocalTransport
from node_transport.msgs import String
from node_transport.qos import EVENTS, Durability, QoS
from node_transport.wire import (
    ENGINE_EVENTS,
    ENGINE_STATUS,
    BridgeCommand,
    BridgeFeedback,
    EngineEvent,
    EngineStatus,
    SmRequest,
    SmResult,
    SmStatus,
    bridge_topic,
    sm_topic,
)
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import create_backend

APPS = Path(__file__).resolve().parents[1] / "apps_xml"
SESSION = re.compile(r"-[0-9a-f]{6}-")  # the random session part of request and command ids
LONG_FLOAT = re.compile(r"-?\d+\.\d{10,}(?:e-?\d+)?")


def _normal(text: str) -> str:
    """Session ids out, and numbers to the nanosecond the wire keeps (a simulated run time may come out
    a float step apart: 24.516791564000002 and 24.516791564)."""
    return LONG_FLOAT.sub(lambda m: f"{float(m.group()):.9f}", SESSION.sub("-S-", text))


def test_a_hand_over_is_received_inside_publish_and_a_plain_subscription_still_a_turn_later(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[str], list[str], list[str], list[str]]:
        bus = LocalTransport(clock)
        a, b = bus.create_node("a"), bus.create_node("b")
        handed: list[str] = []
        plain: list[str] = []
        b.create_subscription(String, "/chatter", lambda m: handed.append(m.data), hand_over=True)
        b.create_subscription(String, "/chatter", lambda m: plain.append(m.data))
        pub = a.create_publisher(String, "/chatter")
        for i in range(3):
            pub.publish(String(str(i)))
        during_handed, during_plain = list(handed), list(plain)
        await clock.sleep(0)
        return during_handed, during_plain, handed, plain

    during_handed, during_plain, handed, plain = run_sim(main)
    assert during_handed == ["0", "1", "2"] and during_plain == []
    assert handed == plain == ["0", "1", "2"]


def test_a_typed_hand_over_gets_the_same_object_checks_as_a_drained_one(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[Any], list[Any]]:
        bus = LocalTransport(clock)
        sender, receiver = bus.create_node("sender"), bus.create_node("receiver")
        pub = TypedPublisher(sender, SmResult, "/g/sm/result")
        handed: list[Any] = []
        refused: list[Any] = []
        subscribe(receiver, SmResult, "/g/sm/result", handed.append, refused.append, hand_over=True)
        pub.publish(SmResult("r1", "g", "succeeded", error="", t_end=1.0))  # "" is None on the wire: decoded, not carried
        pub.publish(SmResult("r2", "g", "aborted", error="boom", t_end=2.0))
        return handed, refused

    handed, refused = run_sim(main)
    assert [(r.id, r.error) for r in handed] == [("r1", None), ("r2", "boom")] and refused == []
    assert all(type(r) is SmResult for r in handed)


def test_a_message_published_from_inside_its_own_hand_over_waits_its_turn(run_sim: Any) -> None:
    """No receiver runs inside its own callback: a message it causes on its own topic queues, in order."""

    async def main(clock: Clock) -> tuple[list[str], list[str]]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        pub = node.create_publisher(String, "/echo", QoS(depth=10))
        log: list[str] = []

        def echo(msg: Any) -> None:
            log.append(f"in {msg.data}")
            if len(msg.data) < 3:
                pub.publish(String(msg.data + "+"))
            log.append(f"out {msg.data}")

        node.create_subscription(String, "/echo", echo, QoS(depth=10), hand_over=True)
        pub.publish(String("a"))
        during = list(log)
        await clock.sleep(0)
        await clock.sleep(0)
        return during, log

    during, log = run_sim(main)
    assert during == ["in a", "out a"]
    assert log == ["in a", "out a", "in a+", "out a+", "in a++", "out a++"]


def test_while_messages_are_queued_for_a_hand_over_later_ones_queue_behind_them(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[str], list[str]]:
        bus = LocalTransport(clock)
        node = bus.create_node("n")
        latched = QoS(depth=5, durability=Durability.TRANSIENT_LOCAL)
        pub = node.create_publisher(String, "/latched", latched)
        pub.publish(String("old"))
        got: list[str] = []
        node.create_subscription(String, "/latched", lambda m: got.append(m.data), latched, hand_over=True)  # the replay is queued
        pub.publish(String("new"))
        during = list(got)
        await clock.sleep(0)
        return during, got

    during, got = run_sim(main)
    assert during == [] and got == ["old", "new"]


def test_a_fault_in_a_hand_over_is_the_receiving_nodes_and_the_publisher_goes_on(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[tuple[str, str]], list[str]]:
        bus = LocalTransport(clock)
        a, b = bus.create_node("a"), bus.create_node("b")
        faults: list[tuple[str, str]] = []
        b.fault_handler = lambda where, error: faults.append((where, str(error)))
        got: list[str] = []

        def take(msg: Any) -> None:
            if msg.data == "bad":
                raise ValueError("cannot use it")
            got.append(msg.data)

        b.create_subscription(String, "/t", take, QoS(depth=10), hand_over=True)
        pub = a.create_publisher(String, "/t", QoS(depth=10))
        for text in ("one", "bad", "two"):
            pub.publish(String(text))
        return faults, got

    faults, got = run_sim(main)
    assert faults == [("subscription /t", "cannot use it")] and got == ["one", "two"]


def test_hand_overs_nest_only_so_deep_then_the_rest_queues(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[int, list[int]]:
        bus = LocalTransport(clock)
        chain = HAND_OVER_DEPTH + 2
        nodes = [bus.create_node(f"n{i}") for i in range(chain + 1)]
        pubs = [nodes[i].create_publisher(String, f"/t{i}") for i in range(chain)]
        reached: list[int] = []

        def relay(i: int) -> Any:
            def take(msg: Any) -> None:
                reached.append(i)
                if i + 1 < chain:
                    pubs[i + 1].publish(msg)
            return take

        for i in range(chain):
            nodes[i + 1].create_subscription(String, f"/t{i}", relay(i), hand_over=True)
        pubs[0].publish(String("x"))
        inside = len(reached)
        await clock.sleep(0)
        return inside, reached

    inside, reached = run_sim(main)
    assert inside == HAND_OVER_DEPTH and reached == list(range(HAND_OVER_DEPTH + 2))


# --------------------------------------------------------------- a machine still takes its turns
class EndlessSpeeds(CoreFunctions):
    """Test only: set_speed after set_speed, each over in the simulator's first step."""

    spoken: ClassVar[list[int]] = []

    @skill(ParamSpec("count", ParamType.INTEGER, "how many", minimum=1), groups=("arm",))
    def speeds(self, count: int) -> Skill:
        """``count`` speed changes."""
        for i in range(count):
            EndlessSpeeds.spoken.append(i)
            yield SetSpeed(0.5 + 0.5 * (i % 2))


def test_a_skill_of_instant_primitives_still_lets_an_operator_stop_it_at_once(run_sim: Any) -> None:
    """The bridge answers inside the machine's publish, so nothing in a primitive makes the machine
    wait: it still gives the loop a turn before each further primitive, or an operator's stop (and
    every other node) would wait for the whole skill."""
    library = FunctionLibrary(
        catalog=lambda chosen: Catalog.from_classes({"core": CoreFunctions, "test": EndlessSpeeds}),
        functions_class=lambda chosen: EndlessSpeeds,
    )
    EndlessSpeeds.spoken.clear()

    async def main(clock: Clock) -> tuple[str, int, int]:
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
        deployment = await deploy_local(clock, NEXTAGE_OPEN, backend, machine_parameters={"trajectory_db": ":memory:"}, library=library)
        try:
            run = asyncio.ensure_future(deployment.engine.run(make_app([{"left_arm": ("speeds", "20000")}])))
            while len(EndlessSpeeds.spoken) < 10:
                await asyncio.sleep(0)
            asked_at = len(EndlessSpeeds.spoken)
            ok, answer = await deployment.engine.operator_command("stop", "test")
            assert ok, answer
            report = await run
            return report.outcome, asked_at, len(EndlessSpeeds.spoken) - asked_at
        finally:
            await deployment.close()

    outcome, asked_at, after_the_stop = run_sim(main)
    assert asked_at <= 12  # the operator had a turn while the skill ran (not after its 20,000 primitives)
    assert outcome == "stopped" and after_the_stop <= 10


# ------------------------------------------------------------------ what observers see is the same
def _observed(hand_over: bool) -> dict[str, list[str]]:
    """Every message of the rivet demonstrator's run on the topics between the nodes, topic by topic,
    as an observer on the same transport decodes them (session ids and epochs aside)."""
    app = load_application(APPS / "rivet_installation.xml", APPLICATION_FUNCTIONS.catalog(None))
    seen: dict[str, list[str]] = {}

    async def main(clock: Clock) -> bool:
        backend = await create_backend("nextage-sim", clock, BackendOptions(robot=app.robot))
        await backend.start()
        transport = LocalTransport(clock, hand_over=hand_over)
        deployment = await deploy_local(clock, app.robot, backend, machine_parameters={"trajectory_db": ":memory:"}, transport=transport)
        node = transport.create_node("observer")

        def watch(topic: str, read: Any) -> None:  # deep queues, as the trace, the recorder and the station have them
            node.create_subscription(read[0], topic, lambda m: seen.setdefault(topic, []).append(_normal(repr(read[1](m)))), EVENTS)

        def wire(cls: type) -> tuple[type, Any]:
            return typed.msg_type(cls), lambda m: typed.from_msg(cls, m, clock)

        state = (typed.MachineStateMsg, lambda m: (typed.read_state(m), round(typed.run_time(clock, m.header.stamp), 6)))
        for group in app.robot.group_names:
            for leaf, cls in (("request", SmRequest), ("result", SmResult), ("status", SmStatus)):
                watch(sm_topic(group, leaf), wire(cls))
            watch(sm_topic(group, "state"), state)
            watch(bridge_topic(group, "command"), wire(BridgeCommand))
            watch(bridge_topic(group, "feedback"), wire(BridgeFeedback))
        watch(ENGINE_STATUS, wire(EngineStatus))
        watch(ENGINE_EVENTS, wire(EngineEvent))
        try:
            return (await deployment.engine.run(app)).ok
        finally:
            await deployment.close()

    assert run_with_clock(main, simulated_clock())
    return seen


def test_hand_overs_change_nothing_an_observer_sees_on_any_topic() -> None:
    """The rivet demonstrator with and without hand-overs: on every topic between the engine, the
    machines and the bridge, the same messages in the same order (only the order across topics may
    differ, which no transport guarantees)."""
    with_hand_overs, without = _observed(True), _observed(False)
    assert with_hand_overs.keys() == without.keys() and len(with_hand_overs) == 3 * 6 + 2
    for topic, messages in without.items():
        assert with_hand_overs[topic] == messages, topic
    assert sum(map(len, without.values())) > 1000
