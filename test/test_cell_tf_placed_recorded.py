"""A recording of a cell of several robots holds every robot's ``tf``, worked out in the encoder as for one robot.

``run --record`` does not make the bridges compute ``tf`` for the recorder: the encoder works it out of the recorded
``joint_states`` and URDFs (execution_engine/recorder/derived_tf.py).  In a cell each robot's bridge publishes its
URDF on ``/<robot>/robot_description`` (placed in the cell's world, under the cell's prefix) and its own joint
states; the recording's ``tf`` must be what a listener gets from the bridges -- byte for byte, at the same log
times -- for every robot, so Foxglove replays the whole cell.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from test_recorded_tf import Memory

from core_functions.geometry import Pose
from execution_engine.recorder.recorder import Recorder
from execution_engine.recorder.writer import McapSink
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import Header, JointState
from node_transport.qos import SENSOR
from node_transport.wire import JOINT_STATES
from robot_bridges.placed_urdf import placed_urdf
from robot_bridges.robot_state import RobotStatePublisher

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = {  # robot -> (URDF, base, prefix), as apps_xml/examples/cells/side_by_side_cell.xml places them
    "loader": (ROOT / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf", Pose(), "kuka_"),
    "checker": (ROOT / "robot_bridges" / "vplus" / "urdf" / "adept_viper_s850.urdf", Pose.from_xyz_rpy(1.5, 0.0, 0.0, 0.0, 0.0, 3.14159265), "viper_"),
}


def tf_messages(memory: Memory) -> list[tuple[int, bytes]]:
    """The recording's /tf messages: (log time, CDR bytes)."""
    return [(m.log_time, m.data) for _, _, m in make_reader(io.BytesIO(memory.getvalue())).iter_messages(topics=["/tf"])]


async def _cell_run(clock: Clock, recorders: dict[str, bool], steps: int) -> dict[str, Memory]:
    """Each robot's bridge: its joint_states, then its tf from the same positions and stamp, in turns."""
    transport = LocalTransport(clock)
    robots = []
    for name, (urdf, base, prefix) in ROBOTS.items():
        node = transport.create_node(f"{name}_bridge")
        placed = placed_urdf(urdf.read_text(), base, prefix, f"{prefix}mount")
        robots.append((node.create_publisher(JointState, JOINT_STATES, SENSOR), RobotStatePublisher(node, placed, f"/{name}/robot_description"), node))
    files = {name: Memory() for name in recorders}  # one recording working tf out, one receiving the bridges' tf
    running = [Recorder(transport.create_node(f"recorder_{name}"), McapSink(files[name], name), derive_tf=derive) for name, derive in recorders.items()]
    for recorder in running:
        recorder.start()
    await clock.sleep(0.1)
    rng = np.random.default_rng(5)
    for _ in range(steps):
        for joints, robot, node in robots:
            names = robot.tree.movable_joints
            state = tuple(float(v) for v in rng.uniform(-1.0, 1.0, len(names)))
            stamp = node.now_stamp()
            joints.publish(JointState(header=Header(stamp=stamp), name=names, position=state))
            robot.publish(names, state, stamp)
        await clock.sleep(0.05)
    for recorder in running:
        stats = await recorder.close()
        assert not stats.error and not stats.dropped
    return files


def test_the_recorded_tf_of_a_cell_is_every_robots_as_a_listener_gets_it(run_sim: Any) -> None:
    files = run_sim(lambda clock: _cell_run(clock, {"derived": True, "received": False}, 20))
    derived, received = tf_messages(files["derived"]), tf_messages(files["received"])
    assert len(received) == 2 * 20  # one per joint state of each robot
    assert derived == received  # the same CDR bytes at the same log times
