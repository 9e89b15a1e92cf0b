"""The ROS picture of a cell of several robots over DDS, as ``launch`` starts it: one bridge process per robot.

``launch APP --transport dds --nodes <the robots' bridges>`` (the command a cell's bridge PC runs) starts each
robot's bridge with its base pose and the cell's names as parameters; a viewer in the same domain -- this test,
another DDS participant -- receives each robot's URDF on ``/<robot>/robot_description``, ``/joint_states``,
``/tf_static`` and ``/tf`` off the wire and finds the same picture as in-process (cell_picture.check: the URDFs
parse, their joints exactly those on /joint_states, the tf chain from ``world`` to each TCP the bridge's TCP).
In real time (DDS has no simulated clock): the bridges' start-up, then a few state periods.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from cell_picture import Picture, check
from dds_domain import stop_group
from test_cell_tf_placed import EXAMPLES, cell_robot

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.port import poll_until

ROOT = Path(__file__).resolve().parents[1]
BOUND = 90.0  # s: two bridge processes' start-up (pinocchio, the RSI handshake) on a loaded machine


@pytest.mark.parametrize("app", ["side_by_side.xml", "mixed_cell.xml"])
def test_launchs_bridge_processes_show_every_robot_at_its_base_over_dds(tmp_path: Path, dds_env: dict[str, str], app: str) -> None:
    robot = cell_robot(app)
    bridges = ",".join(f"{m.name}_bridge" for m in robot.members)
    env = {**os.environ, **dds_env, "XDG_DATA_HOME": str(tmp_path / "data"), "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen(
        [sys.executable, "-m", "execution_engine", "launch", str(EXAMPLES / app), "--transport", "dds", "--nodes", bridges],
        cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True,
    )

    async def view(clock: Clock) -> tuple[Picture, bool]:
        transport = DdsTransport(clock, [], env=dds_env)
        picture = Picture()
        picture.listen(transport.create_node("rviz"), robot)
        try:
            complete = await poll_until(clock, lambda: picture.complete(robot) or process.poll() is not None, BOUND, 0.1)
            return picture, complete and process.poll() is None
        finally:
            await transport.shutdown()

    try:
        picture, complete = run_with_clock(view, real_clock())
    finally:
        stop_group(process)
    out = process.stdout.read() if process.stdout else ""
    assert complete, out
    check(picture, robot)
