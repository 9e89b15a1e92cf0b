"""The DDS transport on the wire: loopback only, a domain of its own (dds_domain.py), every wait bounded.

Two transports in one test are two DDS participants, as two node processes would be; the
liveliness test kills a real publisher process.  Waits are on conditions with a deadline
(:func:`poll_until`), never a fixed sleep; the DDS transport runs on the wall clock by design.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any

import pytest
from dds_domain import domain_env

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport import dds_graph
from node_transport.dds import DdsTransport
from node_transport.dds_args import parse_ros_arguments, user_arguments
from node_transport.msgs import Header, JointState, String, Time, Trigger, TriggerResponse
from node_transport.port import RosArgumentsError, ServiceUnavailable, TransportError, poll_until
from node_transport.qos import COMMANDS, LATCHED, SENSOR
from node_transport.selection import split_transport

ROOT = Path(__file__).resolve().parent.parent
BOUND = 10.0  # seconds any one condition may take on a loaded machine


@pytest.fixture(scope="module")
def env() -> Iterator[dict[str, str]]:
    """A domain of its own on loopback, so parallel runs and other cells never meet this one (dds_domain.py)."""
    with domain_env() as claimed:
        yield claimed


def run_real(main: Callable[[Clock], Coroutine[Any, Any, Any]]) -> Any:
    return run_with_clock(main, real_clock())


async def until(clock: Clock, condition: Callable[[], bool], what: str) -> None:
    assert await poll_until(clock, condition, BOUND, 0.01), f"not within {BOUND} s: {what}"


def test_topics_latched_late_joiner_and_services_between_participants(env: dict[str, str]) -> None:
    async def main(clock: Clock) -> None:
        a, b = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        try:
            bridge, viewer = a.create_node("bridge"), b.create_node("viewer")
            description = bridge.create_publisher(String, "robot_description", LATCHED)
            description.publish(String("<robot name='nextage'/>"))
            states = bridge.create_publisher(JointState, "joint_states", SENSOR)
            got: list[Any] = []
            viewer.create_subscription(JointState, "joint_states", got.append, SENSOR)
            late: list[String] = []
            viewer.create_subscription(String, "robot_description", late.append, LATCHED)  # after the publish
            await until(clock, lambda: states.get_subscription_count() == 1, "joint_states matched")
            sent = JointState(Header(Time(1_700_000_000, 25), ""), ("j1", "j2"), (0.5, -0.25), (), ())
            await until(clock, lambda: (states.publish(sent), bool(got))[1], "a joint state delivered")
            assert got[0] == sent
            await until(clock, lambda: bool(late), "the latched description reached the late subscriber")
            assert late == [String("<robot name='nextage'/>")]

            calls: list[str] = []

            async def pause(_request: Any) -> TriggerResponse:
                calls.append("pause")
                return TriggerResponse(True, "paused")

            bridge.create_service(Trigger, "execution_engine/pause", pause)
            client = viewer.create_client(Trigger, "/execution_engine/pause")
            assert await client.call(Trigger.Request(), timeout=BOUND) == TriggerResponse(True, "paused")
            assert calls == ["pause"]
            nobody = viewer.create_client(Trigger, "nobody/serves")
            with pytest.raises(ServiceUnavailable):
                await nobody.call(Trigger.Request(), timeout=0.3)
        finally:
            await a.shutdown()
            await b.shutdown()

    run_real(main)


def test_a_failing_handler_answers_failure_and_reports_the_fault(env: dict[str, str]) -> None:
    async def main(clock: Clock) -> tuple[Any, list[str]]:
        transport = DdsTransport(clock, env=env)
        faults: list[str] = []
        try:
            node = transport.create_node("server")
            node.fault_handler = lambda where, error: faults.append(f"{where}: {error}")

            async def broken(_request: Any) -> TriggerResponse:
                raise RuntimeError("the arm is not homed")

            node.create_service(Trigger, "home", broken)
            client = transport.create_node("caller").create_client(Trigger, "/home")
            return await client.call(Trigger.Request(), timeout=BOUND), faults
        finally:
            await transport.shutdown()

    response, faults = run_real(main)
    assert response.success is False and "the arm is not homed" in response.message
    assert faults == ["service /home: the arm is not homed"]


def test_ros_discovery_info_lists_each_node_with_its_endpoints(env: dict[str, str]) -> None:
    """What `ros2 node list` and `ros2 topic info -v` read: ParticipantEntitiesInfo on ros_discovery_info."""
    async def main(clock: Clock) -> None:
        # optional: cyclonedds (pip extra 'dds'), a plain DDS reader
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        ours, tool = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        try:
            machine = ours.create_node("left_arm_machine", namespace="/cell_a")
            publisher = machine.create_publisher(String, "left_arm/sm/state", LATCHED)
            machine.create_subscription(String, "left_arm/sm/request", lambda _m: None, COMMANDS)
            info_type = tool.registry.message(dds_graph.DISCOVERY_TYPE)
            reader = DataReader(tool.participant, Topic(tool.participant, "ros_discovery_info", info_type), qos=dds_graph.dds_qos(dds_graph.DISCOVERY))
            seen: dict[str, Any] = {}

            def read() -> bool:
                for sample in reader.take(N=10):
                    if bytes(sample.gid.data) == ours.participant.guid.bytes:
                        seen["info"] = sample
                info = seen.get("info")
                return info is not None and any(n.node_name == "left_arm_machine" for n in info.node_entities_info_seq)

            await until(clock, read, "the node announced")
            node = next(n for n in seen["info"].node_entities_info_seq if n.node_name == "left_arm_machine")
            assert node.node_namespace == "/cell_a"
            assert publisher.writer.guid.bytes in [bytes(g.data) for g in node.writer_gid_seq]
            assert len(node.reader_gid_seq) == 1
        finally:
            await ours.shutdown()
            await tool.shutdown()

    run_real(main)


def test_garbage_on_a_topic_is_counted_and_the_topic_keeps_working(env: dict[str, str]) -> None:
    """Raw samples written onto /joint_states as a broken peer would: truncated CDR never leaves a
    Cyclone writer; CDR that is well-formed but not a JointState (names that are not UTF-8) reaches
    the reader and is rejected and counted, nothing reaches the callback, nothing crashes, and the
    good samples after it still arrive."""
    async def main(clock: Clock) -> None:
        from cyclonedds._clayer import ddspy_write  # optional: cyclonedds (pip extra 'dds'); raw CDR out

        ours, rogue = DdsTransport(clock, env=env), DdsTransport(clock, env=env)
        try:
            got: list[JointState] = []
            ours.create_node("viewer").create_subscription(JointState, "joint_states", got.append, SENSOR)
            robot = rogue.create_node("robot").create_publisher(JointState, "/joint_states", SENSOR)
            await until(clock, lambda: robot.get_subscription_count() == 1, "matched")
            whole = rogue.converter.to_wire(JointState(name=("j1", "j2"), position=(1.0, 2.0))).serialize()
            for cut in (whole[:12], whole[:-9]):  # truncated CDR: Cyclone refuses it before the wire
                assert ddspy_write(robot.writer._ref, cut.ljust((len(cut) + 3) & ~3, b"\0")) < 0
            # well-formed CDR that is still garbage: names that are not UTF-8
            bad_name = whole.replace(b"j1\0", b"\xff\xfe\0")
            garbage = [bad_name, bad_name]
            for data in garbage:
                assert ddspy_write(robot.writer._ref, data) >= 0
            await until(clock, lambda: ours.rejected["/joint_states"] >= len(garbage), "every bad sample counted")
            assert got == []
            good = JointState(name=("j",), position=(1.0,))
            await until(clock, lambda: (robot.publish(good), bool(got))[1], "good samples after garbage")
            assert set(got) == {good}
        finally:
            await ours.shutdown()
            await rogue.shutdown()

    run_real(main)


PUBLISHER = """
import asyncio, sys
from node_transport.clock import real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.msgs import String
from node_transport.qos import COMMANDS

async def main(clock):
    transport = DdsTransport(clock)
    transport.create_node("doomed").create_publisher(String, "left_arm/sm/result", COMMANDS)
    print("ready", flush=True)
    await asyncio.get_running_loop().create_future()

run_with_clock(main, real_clock())
"""


def test_a_killed_peer_leaves_the_publisher_count_within_the_liveliness_lease(env: dict[str, str]) -> None:
    """kill -9 sends no goodbye: the writer's liveliness lease (1 s) is what tells the reader."""
    child = subprocess.Popen(
        [sys.executable, "-c", PUBLISHER], cwd=ROOT, env={**os.environ, **env, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE, text=True,
    )
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "ready"

        async def main(clock: Clock) -> float:
            transport = DdsTransport(clock, env=env)
            try:
                sub = transport.create_node("engine").create_subscription(String, "left_arm/sm/result", lambda _m: None, COMMANDS)
                await until(clock, lambda: sub.get_publisher_count() == 1, "the publisher matched and alive")
                # who publishes, from the peer's ros_discovery_info: a watcher names the node it loses
                await until(clock, lambda: sub.publisher_nodes() == ["/doomed"], "the publisher's node named")
                child.send_signal(signal.SIGKILL)
                killed = clock.now()
                await until(clock, lambda: sub.get_publisher_count() == 0, "the killed publisher dropped out")
                return clock.now() - killed
            finally:
                await transport.shutdown()

        noticed = run_real(main)
        assert noticed <= transport_lease() + 1.0  # the lease, plus Cyclone's lease check period
    finally:
        child.kill()
        child.wait(timeout=BOUND)


def transport_lease() -> float:
    return 1.0


# ---------------------------------------------------------------------- configuration, arguments
def test_domain_and_discovery_configuration_follow_rmw() -> None:
    assert dds_graph.domain_id({}) == 0 and dds_graph.domain_id({"ROS_DOMAIN_ID": "42"}) == 42
    with pytest.raises(TransportError, match="0..232"):
        dds_graph.domain_id({"ROS_DOMAIN_ID": "300"})
    local = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    assert local is not None and "<AllowMulticast>false</AllowMulticast>" in local and '<Peer address="localhost"/>' in local
    peers = dds_graph.domain_config({"ROS_STATIC_PEERS": "10.0.0.2;cellpc", "CYCLONEDDS_URI": "file:///etc/cyclone.xml"})
    assert peers is not None and '<Peer address="10.0.0.2"/><Peer address="cellpc"/>' in peers and peers.endswith(",file:///etc/cyclone.xml")
    assert dds_graph.domain_config({}) is None  # SUBNET without peers: Cyclone's own defaults
    off = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "10.0.0.2"})
    assert off is not None and "ros_discovery_off_" in off and "10.0.0.2" not in off
    with pytest.raises(TransportError):
        dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "everywhere"})
    with pytest.raises(TransportError):
        dds_graph.domain_config({"ROS_STATIC_PEERS": '"/><Evil'})
    assert dds_graph.topic_name("/joint_states") == "rt/joint_states"
    assert dds_graph.request_topic("/execution_engine/pause") == "rq/execution_engine/pauseRequest"
    assert dds_graph.reply_topic("/execution_engine/pause") == "rr/execution_engine/pauseReply"


def test_ros_arguments_as_rcl_reads_them(tmp_path: Path) -> None:
    params = tmp_path / "p.yaml"
    params.write_text("/**/left_arm_machine:\n  ros__parameters:\n    group: left_arm\n    bridge_timeout: 5.0\n/**/other:\n  ros__parameters:\n    group: x\n")
    args = parse_ros_arguments(["prog", "--ros-args", "-r", "__node:=left_arm_machine", "--params-file", str(params), "-p", "bridge_timeout:=2", "-r", "/clock:=clock", "--log-level", "debug"])
    assert args.node_name == "left_arm_machine" and args.remaps == {"/clock": "clock"}
    assert args.overrides_for("/left_arm_machine") == {"group": "left_arm", "bridge_timeout": 2}
    assert user_arguments(["prog", "extra", "--ros-args", "-p", "a:=1", "--", "more"]) == ["extra", "more"]
    for bad, message in ((["-p", "speed"], "parameter override"), (["--bogus"], "unknown ROS argument"), (["--params-file", str(tmp_path / "none.yaml")], "cannot read")):
        with pytest.raises(RosArgumentsError, match=message):
            parse_ros_arguments(["prog", "--ros-args", *bad])


def test_transport_option_outside_ros_args() -> None:
    assert split_transport(["prog", "--transport", "dds", "--ros-args", "-p", "a:=1"]) == ("dds", ["prog", "--ros-args", "-p", "a:=1"])
    assert split_transport(["prog", "--transport=ros"]) == ("ros", ["prog"])
    assert split_transport(["prog"]) == ("ros", ["prog"])
    with pytest.raises(RosArgumentsError, match="use one of"):
        split_transport(["prog", "--transport", "zenoh"])


def test_a_node_takes_its_name_parameters_and_remaps_from_the_command_line(env: dict[str, str], tmp_path: Path) -> None:
    async def main(clock: Clock) -> tuple[str, Any, str]:
        argv = ["prog", "--ros-args", "-r", "__node:=left_arm_machine", "-r", "__ns:=/cell_a", "-p", "group:=left_arm", "-r", "chatter:=talk"]
        transport = DdsTransport(clock, argv, env=env)
        try:
            node = transport.create_node("group_machine")
            return node.fully_qualified_name, node.declare_parameter("group", "", "the group"), node.resolve("chatter")
        finally:
            await transport.shutdown()

    assert run_real(main) == ("/cell_a/left_arm_machine", "left_arm", "/cell_a/talk")
