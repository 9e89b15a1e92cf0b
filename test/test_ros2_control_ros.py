"""The ros2-control back end's link under rclpy (``transport=ros``), on the fake rclpy: the driver stand-in and the
back end as two nodes of the rclpy transport, control_msgs' FollowJointTrajectory and GripperCommand carried as
rosidl's classes (built from the same interface files).  A joint move and a grip reach the driver and end as it
says; a goal it refuses is the back end's fault with the driver's words."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from fake_fjt_server import R, FakeDriver
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from test_ros_transport import run_real, with_transport

from core_functions.primitives import EndEffector, MoveJoints
from core_functions.robots import KUKA_KR
from node_transport.clock import Clock
from node_transport.ros import RosTransport
from robot_bridges.backend import BackendOptions, BridgeError, FaultKind
from robot_bridges.ros2_control.backend import Ros2ControlBackend
from robot_bridges.ros2_control.link import GraphLink
from robot_bridges.ros2_control.options import parse_options

URDF = (Path(__file__).resolve().parents[1] / "robot_bridges" / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf").read_text()
CONTROLLER = "/joint_trajectory_controller/follow_joint_trajectory"
GRIPPER = "/gripper_controller/gripper_cmd"


def test_a_move_a_grip_and_a_refusal_under_rclpy(fake_rclpy: Any) -> None:
    async def body(transport: RosTransport) -> dict[str, Any]:
        clock = transport.clock
        driver = FakeDriver(transport.create_node("controller_manager"), clock, URDF, {CONTROLLER: KUKA_KR.group("arm").joint_names},
                            KUKA_KR.poses["home"], gripper=GRIPPER)
        settings = parse_options(BackendOptions(robot=KUKA_KR, extra={"transport": "ros", "arm.controller": CONTROLLER, "arm.gripper": GRIPPER}))
        backend = Ros2ControlBackend(clock, KUKA_KR, settings, GraphLink(transport.create_node("ros2_control_client"), settings))
        try:
            await backend.start()
            target = tuple(math.radians(v) for v in (10, -85, 88, 0, 5, 0))
            moved = await backend.execute("arm", MoveJoints(target))
            await backend.execute("arm", EndEffector("gripper_close"))
            driver.refuse = (R.GOAL_TOLERANCE_VIOLATED, "A2 stopped 0.05 rad short")
            try:
                await backend.execute("arm", MoveJoints(tuple(math.radians(v) for v in (0, -90, 90, 0, 0, 0))))
            except BridgeError as error:
                refused: BridgeError | None = error
            else:
                refused = None
            return dict(moved=moved, target=target, driver=driver, refused=refused)
        finally:
            await driver.close()

    async def main(clock: Clock) -> dict[str, Any]:
        return await with_transport(clock, body)

    out = run_real(main)
    assert [g.outcome for g in out["driver"].goals] == ["succeeded", "refused"]
    assert all(abs(a - b) < 0.01 for a, b in zip(out["moved"].positions, out["target"]))
    assert out["driver"].grips == [0.0]
    refused = out["refused"]
    assert refused is not None and refused.kind is FaultKind.CONTROLLER and "GOAL_TOLERANCE_VIOLATED: A2 stopped 0.05 rad short" in str(refused)
