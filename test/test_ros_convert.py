"""Mirror <-> rosidl conversion, QoS profiles and parameter values, against rosidl-shaped fakes."""
from __future__ import annotations

import array
import math
import sys
import types

import pytest
import ros_fake_msgs
import ros_fake_qos
import ros_fakes
from hypothesis import given
from hypothesis import strategies as st

from node_transport import msgs
from node_transport.port import TransportError
from node_transport.qos import (
    COMMANDS,
    DIAGNOSTICS,
    EVENTS,
    LATCHED,
    ROBOT_DESCRIPTION,
    SENSOR,
    TF,
    TF_STATIC,
    Durability,
    History,
    QoS,
    Reliability,
)
from node_transport.ros_convert import (
    MessageConverter,
    failure_response,
    import_ros_type,
    plain_parameter_value,
    qos_profile,
    user_overrides,
)

converter = MessageConverter(ros_fake_msgs.resolve)

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
names = st.text(max_size=12)
times = st.builds(msgs.Time, sec=st.integers(0, 2**31 - 1), nanosec=st.integers(0, 999_999_999))
headers = st.builds(msgs.Header, stamp=times, frame_id=names)
joint_states = st.builds(
    msgs.JointState,
    header=headers,
    name=st.lists(names, max_size=15).map(tuple),
    position=st.lists(finite, max_size=15).map(tuple),
    velocity=st.lists(finite, max_size=15).map(tuple),
    effort=st.lists(finite, max_size=3).map(tuple),
)
pose_stamped = st.builds(
    msgs.PoseStamped,
    header=headers,
    pose=st.builds(
        msgs.Pose,
        position=st.builds(msgs.Point, finite, finite, finite),
        orientation=st.builds(msgs.Quaternion, finite, finite, finite, finite),
    ),
)

tf_messages = st.builds(
    msgs.TFMessage,
    st.lists(
        st.builds(
            msgs.TransformStamped,
            header=headers,
            child_frame_id=names,
            transform=st.builds(
                msgs.Transform, st.builds(msgs.Vector3, finite, finite, finite), st.builds(msgs.Quaternion, finite, finite, finite, finite)
            ),
        ),
        max_size=4,
    ).map(tuple),
)
diagnostic_arrays = st.builds(
    msgs.DiagnosticArray,
    header=headers,
    status=st.lists(
        st.builds(
            msgs.DiagnosticStatus,
            level=st.binary(min_size=1, max_size=1),
            name=names,
            message=names,
            hardware_id=names,
            values=st.lists(st.builds(msgs.KeyValue, names, names), max_size=3).map(tuple),
        ),
        max_size=3,
    ).map(tuple),
)


@given(st.one_of(
    st.builds(msgs.String, names),
    st.builds(msgs.Bool, st.booleans()),
    joint_states,
    pose_stamped,
    tf_messages,
    diagnostic_arrays,
    st.builds(msgs.TriggerResponse, st.booleans(), names),
    st.just(msgs.TriggerRequest()),
))
def test_every_mirror_round_trips_through_its_rosidl_class(msg: object) -> None:
    ros = converter.to_ros(msg)
    assert type(ros) is converter.ros_class(type(msg))
    assert converter.from_ros(type(msg), ros) == msg


def test_sequences_and_nested_messages_take_the_shapes_rclpy_uses() -> None:
    state = msgs.JointState(
        header=msgs.Header(msgs.Time(12, 500), "WAIST"), name=("CHEST_JOINT0", "HEAD_JOINT0"), position=(0.1, -0.2)
    )
    ros = converter.to_ros(state)
    assert isinstance(ros.header, ros_fake_msgs.Header) and isinstance(ros.header.stamp, ros_fake_msgs.Time)
    assert (ros.header.stamp.sec, ros.header.stamp.nanosec, ros.header.frame_id) == (12, 500, "WAIST")
    assert ros.name == ["CHEST_JOINT0", "HEAD_JOINT0"]
    assert isinstance(ros.position, array.array) and list(ros.position) == [0.1, -0.2]
    back = converter.from_ros(msgs.JointState, ros)
    assert back.position == (0.1, -0.2) and type(back.position) is tuple and type(back.header.stamp) is msgs.Time


def test_integers_in_float_fields_are_sent_as_floats_rosidl_accepts() -> None:
    # rosidl setters refuse an int for a float64 field; mirrors do not enforce types.
    ros = converter.to_ros(msgs.PoseStamped(pose=msgs.Pose(msgs.Point(1, 2, 3))))  # type: ignore[arg-type]
    assert (ros.pose.position.x, ros.pose.position.y, ros.pose.position.z) == (1.0, 2.0, 3.0)
    assert all(type(v) is float for v in (ros.pose.position.x, ros.pose.orientation.w))


def test_a_value_of_the_wrong_kind_is_refused_naming_its_field() -> None:
    with pytest.raises(TransportError, match=r"'pose\.position\.y'.*number"):
        converter.to_ros(msgs.PoseStamped(pose=msgs.Pose(msgs.Point(0.0, "high", 0.0))))  # type: ignore[arg-type]
    with pytest.raises(TransportError, match=r"'position\[1\]'"):
        converter.to_ros(msgs.JointState(position=(0.0, None)))  # type: ignore[arg-type]
    with pytest.raises(TransportError, match="'data'.*bool"):
        converter.to_ros(msgs.Bool(1))  # type: ignore[arg-type]


def test_a_received_message_that_does_not_fit_the_mirror_is_refused_naming_its_field() -> None:
    ros = ros_fake_msgs.JointState(name=["a"], position=[0.5])
    object.__setattr__(ros, "_name", ["a", 7])  # what a mis-typed peer could deliver
    with pytest.raises(TransportError, match=r"'name\[1\]'"):
        converter.from_ros(msgs.JointState, ros)
    with pytest.raises(TransportError, match="no field 'data'"):
        converter.from_ros(msgs.String, ros_fake_msgs.Point())


def test_an_installed_type_missing_a_mirror_field_is_refused_before_any_message() -> None:
    stale = ros_fake_msgs.message_class("JointState", {"header": "std_msgs/Header", "name": "sequence<string>"}, {"header": ros_fake_msgs.Header})

    def resolver(ros_type: str) -> type:
        return stale if ros_type == "sensor_msgs/msg/JointState" else ros_fake_msgs.resolve(ros_type)

    with pytest.raises(TransportError, match="sensor_msgs/msg/JointState.*position, velocity, effort"):
        MessageConverter(resolver).ros_class(msgs.JointState)


def test_a_ros_byte_travels_as_bytes_of_length_one() -> None:
    # rosidl generates ``byte level`` as an 'octet' held in bytes of length 1; its setter refuses an int.
    status = msgs.DiagnosticStatus(level=msgs.DiagnosticStatus.WARN, name="left_arm_machine: left_arm")
    ros = converter.to_ros(status)
    assert ros.level == b"\x01" and type(ros.level) is bytes
    assert converter.from_ros(msgs.DiagnosticStatus, ros) == status
    assert converter.from_ros(msgs.DiagnosticStatus, ros_fake_msgs.DiagnosticStatus(level=bytearray(b"\x03"))).level == b"\x03"
    for wrong in (1, b"", b"\x00\x01", "1"):
        with pytest.raises(TransportError, match="field 'level': expected one byte"):
            converter.to_ros(msgs.DiagnosticStatus(level=wrong))  # type: ignore[arg-type]


def test_extra_rosidl_fields_keep_their_defaults() -> None:
    # rosidl gives an empty request a placeholder member; the mirror has no fields at all.
    ros = converter.to_ros(msgs.TriggerRequest())
    assert ros.structure_needs_at_least_one_member == 0


def test_service_classes_come_from_the_service_type() -> None:
    service, request, response = converter.service_classes(msgs.Trigger)
    assert (service, request, response) == (ros_fake_msgs.Trigger, ros_fake_msgs.Trigger.Request, ros_fake_msgs.Trigger.Response)
    with pytest.raises(TransportError, match="not a service mirror"):
        converter.service_classes(msgs.String)


def test_every_mirror_names_a_type_of_the_interface_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    ros_fakes.install(monkeypatch)
    real = MessageConverter()  # the default resolver imports from sys.modules
    for mirror in msgs.MESSAGE_TYPES:
        assert real.ros_class(mirror) is ros_fake_msgs.resolve(mirror.ROS_TYPE)
    for service in msgs.SERVICE_TYPES:
        assert real.service_classes(service)[0] is ros_fake_msgs.Trigger


def test_importing_ros_types(monkeypatch: pytest.MonkeyPatch) -> None:
    ros_fakes.install(monkeypatch)
    assert import_ros_type("std_srvs/srv/Trigger_Response") is ros_fake_msgs.Trigger.Response
    assert import_ros_type("geometry_msgs/msg/PoseStamped") is ros_fake_msgs.PoseStamped
    with pytest.raises(TransportError, match="not a ROS interface name"):
        import_ros_type("std_msgs.String")
    with pytest.raises(TransportError, match="has no Strin "):
        import_ros_type("std_msgs/msg/Strin")
    monkeypatch.setitem(sys.modules, "moveit_msgs", types.ModuleType("moveit_msgs"))  # a package nothing here installs
    with pytest.raises(TransportError, match="cannot import moveit_msgs.msg.*sourced"):
        import_ros_type("moveit_msgs/msg/RobotTrajectory")


# ------------------------------------------------------------------------------------ QoS
policies = types.SimpleNamespace(
    QoSProfile=ros_fake_qos.QoSProfile,
    ReliabilityPolicy=ros_fake_qos.ReliabilityPolicy,
    DurabilityPolicy=ros_fake_qos.DurabilityPolicy,
    HistoryPolicy=ros_fake_qos.HistoryPolicy,
)


@pytest.mark.parametrize(
    ("qos", "reliability", "durability", "depth"),
    [
        (COMMANDS, "RELIABLE", "VOLATILE", 50),
        (LATCHED, "RELIABLE", "TRANSIENT_LOCAL", 1),
        (EVENTS, "RELIABLE", "VOLATILE", 1000),
        (SENSOR, "BEST_EFFORT", "VOLATILE", 5),
        (TF, "RELIABLE", "VOLATILE", 100),  # tf2_ros DynamicBroadcasterQoS
        (TF_STATIC, "RELIABLE", "TRANSIENT_LOCAL", 1),  # tf2_ros StaticBroadcasterQoS
        (ROBOT_DESCRIPTION, "RELIABLE", "TRANSIENT_LOCAL", 1),  # robot_state_publisher
        (DIAGNOSTICS, "RELIABLE", "VOLATILE", 10),
    ],
)
def test_named_profiles_map_to_rclpy_policies(qos: QoS, reliability: str, durability: str, depth: int) -> None:
    profile = qos_profile(qos, policies)
    assert profile.reliability is ros_fake_qos.ReliabilityPolicy[reliability]
    assert profile.durability is ros_fake_qos.DurabilityPolicy[durability]
    assert profile.history is ros_fake_qos.HistoryPolicy.KEEP_LAST
    assert profile.depth == depth


def test_keep_all_and_missing_policies() -> None:
    profile = qos_profile(QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_ALL, 0), policies)
    assert profile.history is ros_fake_qos.HistoryPolicy.KEEP_ALL
    old = types.SimpleNamespace(**{**vars(policies), "HistoryPolicy": types.SimpleNamespace(KEEP_LAST=1)})
    with pytest.raises(TransportError, match="history policy KEEP_ALL"):
        qos_profile(QoS(history=History.KEEP_ALL, depth=0), old)


# ------------------------------------------------------------------------ responses, parameters
def test_failure_response_says_what_went_wrong() -> None:
    response = failure_response(msgs.TriggerResponse, "pause: TimeoutError: no answer")
    assert response == msgs.TriggerResponse(False, "pause: TimeoutError: no answer")


def test_overrides_leave_out_what_rclpy_declares_and_give_lists() -> None:
    given = {
        "use_sim_time": False,
        "start_type_description_service": True,
        "qos_overrides./joint_states.publisher.depth": 5,
        "speed": 10.0,
        "faults": ("right_arm:vision",),
        "weights": array.array("d", [0.5, 1.5]),
    }
    assert user_overrides(given) == {"speed": 10.0, "faults": ["right_arm:vision"], "weights": [0.5, 1.5]}
    assert plain_parameter_value("x") == "x"
    assert math.isnan(plain_parameter_value(float("nan")))  # type: ignore[arg-type]
