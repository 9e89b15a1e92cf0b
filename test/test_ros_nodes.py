"""The ``ros2 run`` entry points and their shared process code, over the fake rclpy.

Exit codes, messages on bad input, signals and ROS going away are tested through ``run_node``
and the real entry points; a whole cell (engine, three machines, the Nextage simulator) runs an
application with every node on the rclpy adapter.
"""
from __future__ import annotations

import asyncio
import os
import signal
import threading
from pathlib import Path
from typing import Any

import pytest
import ros_fake_context
import ros_fake_msgs
import ros_fake_qos
from execution_engine.recorder.reading import Recording, iter_messages, trace_records
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from cell_runner import nodes
from cell_runner.bridge_nodes.common import run_bridge
from cell_runner.bridge_nodes.nextage_sim import declare_nextage_parameters
from cell_runner.bridge_nodes.nextage_sim import main as nextage_main
from cell_runner.ros_main import ExitCode, Outcome, StartupError, run_node
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.machine.group_machine import GroupMachine
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.port import Node
from node_transport.ros import RosTransport
from node_transport.wire import machine_node_name

BOUND = 20.0  # s: only reached when something hangs

SMOKE_APP = """<application name="ros smoke" robot="nextage_open">
  <operation id="open">
    <left_arm><function name="gripper_open"/></left_arm>
    <right_arm><function name="wait"><params><param name="seconds" value="0.05"/></params></function></right_arm>
  </operation>
  <operation id="close">
    <left_arm><function name="gripper_close"/></left_arm>
    <right_arm><function name="gripper_close"/></right_arm>
  </operation>
</application>
"""


@pytest.fixture(autouse=True)
def private_data_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Group machines open a trajectory store under XDG_DATA_HOME: keep it out of the home directory."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))


def stopped_cleanly() -> bool:
    return not ros_fake_context.CONTEXT.ok() and ros_fake_context.CONTEXT.shutdown_count == 1


# ================================================================================ entry points
def test_engine_without_an_application_says_how_to_give_one(
    fake_rclpy: Any, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    assert nodes.engine_main(["execution_engine", "--ros-args", "-p", "autostrat:=false"]) == ExitCode.USAGE
    assert "parameter 'application' is required: --ros-args -p application:=" in capsys.readouterr().err
    assert "parameter(s) autostrat given but not declared by this node (a typo?)" in caplog.text
    assert stopped_cleanly()


def test_engine_lists_every_problem_of_an_invalid_application(fake_rclpy: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    app = tmp_path / "bad.xml"
    app.write_text(SMOKE_APP.replace("gripper_close", "gripper_clos").replace('robot="nextage_open"', 'robot="nextage_open" colour="red"'))
    code = nodes.engine_main(["execution_engine", "--ros-args", "-p", f"application:={app}"])
    err = capsys.readouterr().err
    assert code == ExitCode.FAILED
    assert f"/execution_engine: cannot run {app}: 3 error(s)\n" in err
    assert f"{app}:1:52: <application> has no attribute colour" in err
    assert err.count("unknown function 'gripper_clos' (did you mean 'gripper_close'?)") == 2
    assert stopped_cleanly()


def test_wrong_parameters_and_arguments_are_usage_errors(fake_rclpy: Any, capsys: pytest.CaptureFixture[str]) -> None:
    assert nodes.engine_main(["execution_engine", "--ros-args", "-p", "autostart:=maybe"]) == ExitCode.USAGE
    assert "parameter 'autostart' must be true or false, got string 'maybe'" in capsys.readouterr().err
    assert nodes.group_machine_main(["group_machine", "--ros-args", "-p", "group:=nose"]) == ExitCode.USAGE
    assert "group 'nose' is not a group of nextage_open" in capsys.readouterr().err
    assert nodes.engine_main(["execution_engine", "app.xml"]) == ExitCode.USAGE
    assert "unexpected argument(s) app.xml; give parameters as: --ros-args -p name:=value" in capsys.readouterr().err
    assert nextage_main(["nextage_sim_bridge", "--ros-args", "-p", "initial_pose:=upside_down"]) == ExitCode.USAGE
    assert "unknown Nextage pose 'upside_down'" in capsys.readouterr().err
    assert nextage_main(["nextage_sim_bridge", "--ros-args", "-p", "speed:=0.0"]) == ExitCode.USAGE
    assert "/nextage_sim_bridge: parameter 'speed' must be a number in [0.01, 1000] x real time, got 0\n" in capsys.readouterr().err


def test_a_machine_not_named_after_its_group_is_flagged(
    fake_rclpy: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    async def run_once(self: GroupMachine) -> None:  # the machine's life, cut short
        return None

    monkeypatch.setattr(GroupMachine, "run", run_once)
    assert nodes.group_machine_main(["group_machine", "--ros-args", "-p", "group:=right_arm"]) == ExitCode.OK
    assert "/group_machine drives right_arm; name it right_arm_machine (-r __node:=right_arm_machine)" in caplog.text


# ============================================================================ process lifecycle
def test_a_signal_stops_the_node_with_the_outcome_so_far(fake_rclpy: Any) -> None:
    seen: list[str] = []

    async def body(node: Node, outcome: Outcome) -> None:
        seen.append(node.fully_qualified_name)
        outcome.code = ExitCode.FAILED
        os.kill(os.getpid(), signal.SIGINT)
        await asyncio.get_running_loop().create_future()

    assert run_node("engine", body, ["engine", "--ros-args", "-r", "__node:=renamed"]) == ExitCode.FAILED
    assert seen == ["/renamed"] and stopped_cleanly()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # handed back as found


def test_rclpy_going_away_stops_the_node(fake_rclpy: Any) -> None:
    async def body(node: Node, outcome: Outcome) -> None:
        threading.Thread(target=fake_rclpy.shutdown).start()
        await asyncio.get_running_loop().create_future()

    assert run_node("engine", body, ["engine"]) == ExitCode.OK


def test_a_dead_executor_is_an_internal_error(fake_rclpy: Any) -> None:
    async def body(node: Node, outcome: Outcome) -> None:
        def broken(msg: Any) -> None:  # a raw rclpy callback, without the adapter's guard
            raise RuntimeError("callback defect")

        ros_node = node.ros_node  # type: ignore[attr-defined]
        ros_node.create_subscription(ros_fake_msgs.String, "/raw", broken, ros_fake_qos.QoSProfile(depth=1))
        raw = ros_node.create_publisher(ros_fake_msgs.String, "/raw", ros_fake_qos.QoSProfile(depth=1))
        deadline = node.clock.now() + BOUND
        while raw.get_subscription_count() == 0 and node.clock.now() < deadline:  # discovery
            await node.clock.sleep(0.005)
        raw.publish(ros_fake_msgs.String(data="x"))
        await node.clock.sleep(BOUND)  # the dead executor ends the process long before this

    assert run_node("engine", body, ["engine"]) == ExitCode.INTERNAL
    assert stopped_cleanly()


def test_body_errors_become_exit_codes(fake_rclpy: Any, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture) -> None:
    async def refuses(node: Node, outcome: Outcome) -> None:
        raise StartupError("robot unreachable at 10.0.0.2:1234", ExitCode.FAILED)

    async def defect(node: Node, outcome: Outcome) -> None:
        raise KeyError("oops")

    assert run_node("vplus_bridge", refuses, ["vplus_bridge"]) == ExitCode.FAILED
    assert "/vplus_bridge: robot unreachable at 10.0.0.2:1234" in capsys.readouterr().err
    assert run_node("vplus_bridge", defect, ["vplus_bridge"]) == ExitCode.INTERNAL
    assert "stopped by an unexpected error" in caplog.text and "KeyError: 'oops'" in caplog.text


# ================================================================================ a whole cell
def _run_ros_cell(app: Path, **engine_parameters: Any) -> ExitCode:
    """The simulator, one machine per group and the engine running ``app`` as ROS nodes; the
    engine's exit code (the machines and the bridge must still be serving when it ends)."""

    async def main(clock: Clock) -> ExitCode:
        transport = RosTransport(clock, ["cell"])
        tasks: list[asyncio.Task[None]] = []
        try:
            bridge = transport.create_node("nextage_sim_bridge", parameters={"speed": 20.0})
            tasks.append(asyncio.ensure_future(run_bridge("nextage-sim", declare_nextage_parameters, bridge, Outcome())))
            for group in NEXTAGE_OPEN.group_names:
                machine = transport.create_node(machine_node_name(group), parameters={"group": group})
                tasks.append(asyncio.ensure_future(nodes.run_group_machine(machine, Outcome())))
            parameters = {"application": str(app), "exit_when_done": True, **engine_parameters}
            engine = transport.create_node("execution_engine", parameters=parameters)
            outcome = Outcome()
            await clock.wait_for(nodes.run_engine(engine, outcome), BOUND)
            assert all(not task.done() for task in tasks)  # machines and bridge serve on
            return outcome.code
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await transport.shutdown()

    return run_with_clock(main, real_clock())


def test_a_cell_of_ros_nodes_runs_an_application_and_reports(fake_rclpy: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    app = tmp_path / "smoke.xml"
    app.write_text(SMOKE_APP)
    assert _run_ros_cell(app) == ExitCode.OK
    out = capsys.readouterr().out
    assert "application ros smoke: FINISHED" in out and "operations: 2/2" in out
    assert stopped_cleanly()


def test_the_engine_records_the_ros_graph_with_its_record_parameter(fake_rclpy: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    app = tmp_path / "smoke.xml"
    app.write_text(SMOKE_APP)
    record = tmp_path / "ros.mcap"
    assert _run_ros_cell(app, record=str(record)) == ExitCode.OK
    assert f"recording {record}:" in capsys.readouterr().out
    recording = Recording(str(record))
    messages = list(iter_messages(record, recording))
    types = {m.topic: m.ros_type for m in messages}
    assert not recording.cut
    # from the first request to the last Finish: nothing of the run's start or end is still on its way
    requests = {g: [m.msg.kind for m in messages if m.topic == f"/{g}/sm/request"] for g in ("left_arm", "right_arm", "torso_head")}
    assert requests == {"left_arm": ["execute", "execute", "end"], "right_arm": ["execute", "execute", "end"], "torso_head": ["end"]}
    for group in ("left_arm", "right_arm", "torso_head"):
        assert [m.msg.state for m in messages if m.topic == f"/{group}/sm/state"][-1] == "Finish"
    assert types["/joint_states"] == "sensor_msgs/msg/JointState"
    ours = "dual_arm_executive_interfaces/msg/"
    assert types["/left_arm/sm/status"] == ours + "MachineStatus" and types["/left_arm/sm/state"] == ours + "MachineState"
    assert types["/execution_engine/status"] == ours + "EngineStatus" and types["/left_arm/bridge/command"] == ours + "BridgeCommand"
    events = list(trace_records(record, Recording(str(record))))
    assert [r for r in events if r["event"] == "function_end" and r["outcome"] == "succeeded"]
    assert stopped_cleanly()
