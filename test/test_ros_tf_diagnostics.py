"""tf and diagnostics through the rclpy adapter, over the fake rclpy and rosidl-shaped fake messages.

The interesting parts are the shapes rosidl gives these types in Python: sequences of
sub-messages (``TFMessage.transforms``, ``DiagnosticArray.status``) and the ROS ``byte`` of
``DiagnosticStatus.level``, which is ``bytes`` of length 1 and refuses an ``int``.
"""
from __future__ import annotations

import asyncio
from typing import Any

import pytest
import ros_fake_msgs
from ros_fakes import fake_rclpy  # noqa: F401 - fixture

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.msgs import (
    DiagnosticArray,
    DiagnosticStatus,
    Header,
    KeyValue,
    Quaternion,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
    Vector3,
)
from node_transport.port import TransportError
from node_transport.qos import DIAGNOSTICS, TF_STATIC
from node_transport.ros import RosTransport
from node_transport.ros_convert import MessageConverter

BOUND = 5.0  # s: only reached when something hangs
converter = MessageConverter(ros_fake_msgs.resolve)

TF_SAMPLE = TFMessage(
    (
        TransformStamped(Header(Time(12, 5), "WAIST"), "part", Transform(Vector3(0.34, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0))),
        TransformStamped(Header(Time(12, 5), "part"), "drill_1", Transform(Vector3(0.0, 0.06, 0.0), Quaternion(0.5, 0.5, 0.5, 0.5))),
    )
)
DIAGNOSTIC_SAMPLE = DiagnosticArray(
    Header(Time(3, 250)),
    (
        DiagnosticStatus(
            DiagnosticStatus.ERROR,
            "left_arm_machine: left_arm",
            "ErrorHandling: joint_limit",
            "left_arm",
            (KeyValue("state", "ErrorHandling"), KeyValue("last_error", "joint_limit")),
        ),
    ),
)


def test_tf_and_diagnostics_take_the_shapes_rosidl_gives_them() -> None:
    tf = converter.to_ros(TF_SAMPLE)
    assert isinstance(tf, ros_fake_msgs.TFMessage) and isinstance(tf.transforms, list)
    assert all(isinstance(t, ros_fake_msgs.TransformStamped) for t in tf.transforms)
    assert tf.transforms[1].transform.rotation.w == 0.5 and tf.transforms[1].child_frame_id == "drill_1"
    assert converter.from_ros(TFMessage, tf) == TF_SAMPLE

    diagnostics = converter.to_ros(DIAGNOSTIC_SAMPLE)
    status = diagnostics.status[0]
    assert status.level == ros_fake_msgs.DiagnosticStatus.ERROR == b"\x02" and isinstance(status.values[0], ros_fake_msgs.KeyValue)
    assert converter.from_ros(DiagnosticArray, diagnostics) == DIAGNOSTIC_SAMPLE
    assert ros_fake_msgs.DiagnosticStatus().level == DiagnosticStatus.OK  # rosidl's default: bytes([0])


def test_a_level_that_is_not_one_byte_is_refused_with_the_field_named() -> None:
    for wrong in (2, b"", b"\x01\x02"):
        with pytest.raises(TransportError, match=r"field 'status\[0\]\.level': expected one byte"):
            converter.to_ros(DiagnosticArray(status=(DiagnosticStatus(level=wrong),)))  # type: ignore[arg-type]
    received = ros_fake_msgs.DiagnosticArray(status=[ros_fake_msgs.DiagnosticStatus(level=b"\x01")])
    assert converter.from_ros(DiagnosticArray, received).status[0].level == DiagnosticStatus.WARN
    with pytest.raises(AssertionError, match="'level' field must be of type 'bytes'"):
        ros_fake_msgs.DiagnosticStatus(level=1)  # what rosidl does with an int


def test_tf_static_and_diagnostics_cross_the_rclpy_adapter(fake_rclpy: Any) -> None:
    async def main(clock: Clock) -> tuple[list[TFMessage], list[DiagnosticArray]]:
        transport = RosTransport(clock, ["test"])
        try:
            talker, listener = transport.create_node("bridge"), transport.create_node("rviz")
            talker.create_publisher(TFMessage, "tf_static", TF_STATIC).publish(TF_SAMPLE)
            diagnostics = talker.create_publisher(DiagnosticArray, "diagnostics", DIAGNOSTICS)
            tf_in: list[TFMessage] = []
            diag_in: list[DiagnosticArray] = []
            listener.create_subscription(TFMessage, "tf_static", tf_in.append, TF_STATIC)  # late: transient local
            listener.create_subscription(DiagnosticArray, "diagnostics", diag_in.append, DIAGNOSTICS)
            deadline = clock.now() + BOUND
            while diagnostics.get_subscription_count() == 0 and clock.now() < deadline:
                await asyncio.sleep(0.01)  # volatile: only a matched reader gets it, as over DDS
            diagnostics.publish(DIAGNOSTIC_SAMPLE)
            while (not tf_in or not diag_in) and clock.now() < deadline:
                await asyncio.sleep(0.01)
            return tf_in, diag_in
        finally:
            await transport.shutdown()

    tf_in, diag_in = run_with_clock(main, real_clock())
    assert tf_in == [TF_SAMPLE] and diag_in == [DIAGNOSTIC_SAMPLE]
