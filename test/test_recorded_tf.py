"""A recording of an in-process run works ``tf`` out of ``joint_states`` in its encoder process.

What a user relies on: the ``tf`` in the file is the one a listener (RViz, Foxglove) gets from
the bridge, message for message and byte for byte, at the same log times; and the bridge does
no kinematics for the recorder, so recording costs the control path no forward kinematics.
Also: finishing a recording under a simulated clock does not let run time race ahead.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader

from core_functions.urdf_tree import UrdfTree
from node_transport.clock import Clock
from execution_engine.recorder.recorder import Recorder
from execution_engine.recorder.writer import McapSink
from node_transport.link_transforms import LinkTransforms
from node_transport.local import LocalTransport
from node_transport.msgs import Header, JointState
from node_transport.qos import SENSOR
from node_transport.wire import JOINT_STATES
from robot_bridges.robot_state import RobotStatePublisher

NEXTAGE_URDF = Path(__file__).resolve().parents[1] / "robot_bridges" / "nextage_sim" / "urdf" / "nextage_open.urdf"


class Memory(io.BytesIO):
    """A recording kept in memory: the sink closes its stream at the end, we still read it."""

    def close(self) -> None:
        pass


def _states(count: int) -> list[np.ndarray]:
    """Joint states where now one joint moves, now several, now none."""
    rng = np.random.default_rng(11)
    names = UrdfTree(NEXTAGE_URDF.read_text()).movable_joints
    states = [rng.uniform(-1.0, 1.0, len(names))]
    for _ in range(count - 1):
        state = states[-1].copy()
        moving = rng.choice(len(names), size=int(rng.integers(0, 4)), replace=False)
        state[moving] = rng.uniform(-1.0, 1.0, len(moving))
        states.append(state)
    return states


async def _bridge_run(clock: Clock, recorders: dict[str, bool], states: list[np.ndarray]) -> dict[str, Memory]:
    """A bridge's state publishing (joint_states, then tf from the same positions and stamp) with
    one recorder per entry of ``recorders`` (name -> derive_tf)."""
    transport = LocalTransport(clock)
    bridge = transport.create_node("bridge")
    joints = bridge.create_publisher(JointState, JOINT_STATES, SENSOR)
    robot = RobotStatePublisher(bridge, NEXTAGE_URDF.read_text())
    names = robot.tree.movable_joints
    files = {name: Memory() for name in recorders}
    running = []
    for name, derive in recorders.items():
        recorder = Recorder(transport.create_node(f"recorder_{name}"), McapSink(files[name], name), derive_tf=derive)
        recorder.start()
        running.append(recorder)
    await clock.sleep(0.1)
    for state in states:
        stamp = bridge.now_stamp()
        joints.publish(JointState(header=Header(stamp=stamp), name=names, position=tuple(float(v) for v in state)))
        robot.publish(names, tuple(float(v) for v in state), stamp)
        await clock.sleep(0.05)
    for recorder in running:
        stats = await recorder.close()
        assert not stats.error and not stats.dropped
    return files


def _messages(memory: Memory, topic: str) -> list[tuple[int, bytes]]:
    reader = make_reader(io.BytesIO(memory.getvalue()))
    return [(m.log_time, m.data) for _, _, m in reader.iter_messages(topics=[topic])]


def _qos(memory: Memory, topic: str) -> str:
    summary = make_reader(io.BytesIO(memory.getvalue())).get_summary()
    assert summary is not None
    return next(c.metadata["offered_qos_profiles"] for c in summary.channels.values() if c.topic == topic)


def test_the_recorded_tf_is_the_one_a_listener_gets_byte_for_byte(run_sim: Any) -> None:
    states = _states(40)
    files = run_sim(lambda clock: _bridge_run(clock, {"derived": True, "received": False}, states))
    derived, received = _messages(files["derived"], "/tf"), _messages(files["received"], "/tf")
    assert len(received) == len(states)
    assert derived == received  # the same CDR bytes at the same log times
    assert [t for t, _ in derived] == [t for t, _ in _messages(files["derived"], "/joint_states")]
    assert _qos(files["derived"], "/tf") == _qos(files["received"], "/tf")


def test_a_recording_that_works_tf_out_costs_the_bridge_no_kinematics(run_sim: Any, monkeypatch: Any) -> None:
    calls: list[int] = []
    moving = LinkTransforms.moving

    def counted(self: LinkTransforms, *args: Any) -> Any:
        calls.append(1)
        return moving(self, *args)

    monkeypatch.setattr(LinkTransforms, "moving", counted)  # the run's process only: the encoder is another
    files = run_sim(lambda clock: _bridge_run(clock, {"derived": True}, _states(10)))
    assert calls == []
    assert len(_messages(files["derived"], "/tf")) == 10


def test_finishing_a_recording_does_not_let_simulated_time_run(run_sim: Any) -> None:
    """The sink finishes in its own threads; meanwhile the cell's periodic tasks must not race ahead."""

    async def main(clock: Clock) -> tuple[float, float, int]:
        transport = LocalTransport(clock)
        talker = transport.create_node("talker")
        joints = talker.create_publisher(JointState, JOINT_STATES, SENSOR)
        ticks = [0]

        async def periodic() -> None:
            while True:
                ticks[0] += 1
                joints.publish(JointState(header=Header(stamp=talker.now_stamp())))
                await clock.sleep(0.05)

        task = clock.loop.create_task(periodic())
        recorder = Recorder(transport.create_node("recorder"), McapSink(Memory(), "memory"))
        recorder.start()
        await clock.sleep(1.0)
        before, ticks_before = clock.now(), ticks[0]
        await recorder.close()
        after = clock.now()
        task.cancel()
        return before, after, ticks[0] - ticks_before

    before, after, ticks = run_sim(main)
    assert after == before and ticks <= 1
