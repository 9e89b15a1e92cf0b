"""The interface files as the one source of the DDS types: parsing, layout, type hashes, mirrors.

The expected type hashes and CDR bytes are what ROS 2 Jazzy's rosidl and rmw_cyclonedds_cpp
produce for the same types (taken from a Jazzy build's ``share/<pkg>/msg/<Name>.json``).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from execution_engine.engine.run_action import RunApplicationGoal, SendGoal
from node_transport import mirrors, msgs, wire
from node_transport.action import UUID
from node_transport.dds_convert import DdsConverter
from node_transport.idl import InterfaceError, InterfaceRegistry, dds_type_name, parse_message
from node_transport.idl_hash import type_hash

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "interfaces" / "dual_arm_executive_interfaces"

JAZZY_HASHES = {
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "sensor_msgs/msg/JointState": "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    "diagnostic_msgs/msg/DiagnosticArray": "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    "rmw_dds_common/msg/ParticipantEntitiesInfo": "RIHS01_91a0593bacdcc50ea9bdcf849a938b128412cc1ea821245c663bcd26f83c295e",
    "tf2_msgs/msg/TFMessage": "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    "std_srvs/srv/Trigger_Request": "RIHS01_d010825374ce8918e72bfd826c82603e60f45419e932ea976f807b74a863a199",
    "std_srvs/srv/Trigger_Response": "RIHS01_2d946c21e2fc3f1e9ca6986a8191d85fcc70097a8bb7771a053564bc47009cdf",
    "sensor_msgs/msg/Image": "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",  # the cameras on DDS (ros2-control, camera-sim)
    "sensor_msgs/msg/CameraInfo": "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    "sensor_msgs/msg/RegionOfInterest": "RIHS01_ad16bcba5f9131dcdba6fbded19f726f5440e3c513b4fb586dd3027eeed8abb1",
    "std_srvs/srv/SetBool_Request": "RIHS01_c62fbb99d94e1b25e8ef9e109f9581956bb1b3361a45a4e5810c36a90d29932e",  # the tool's service (ros2-control)
    "std_srvs/srv/SetBool_Response": "RIHS01_d0814e7f7b4880ab77e9c57426c7aa1562ab69f11eef8e2e968812f9cbd0b059",
    "geometry_msgs/msg/PoseStamped": "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    "action_msgs/msg/GoalStatusArray": "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
    "rcl_interfaces/msg/Log": "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac",
}


@pytest.fixture(scope="module")
def action_registry(tmp_path_factory: pytest.TempPathFactory) -> InterfaceRegistry:
    """With tf2_msgs/action/LookupTransform from Jazzy, whose derived types' hashes Jazzy lists."""
    root = tmp_path_factory.mktemp("interfaces")
    (root / "tf2_msgs" / "action").mkdir(parents=True)
    (root / "tf2_msgs" / "msg").mkdir(parents=True)
    (root / "tf2_msgs" / "action" / "LookupTransform.action").write_text(
        "string target_frame\nstring source_frame\nbuiltin_interfaces/Time source_time\nbuiltin_interfaces/Duration timeout\n"
        "builtin_interfaces/Time target_time\nstring fixed_frame\nbool advanced\n---\n"
        "geometry_msgs/TransformStamped transform\ntf2_msgs/TF2Error error\n---\n"
    )
    (root / "tf2_msgs" / "msg" / "TF2Error.msg").write_text(
        "uint8 NO_ERROR = 0\nuint8 LOOKUP_ERROR = 1\nuint8 CONNECTIVITY_ERROR = 2\nuint8 EXTRAPOLATION_ERROR = 3\n"
        "uint8 INVALID_ARGUMENT_ERROR = 4\nuint8 TIMEOUT_ERROR = 5\nuint8 TRANSFORM_ERROR = 6\nuint8 error\nstring error_string\n"
    )
    return InterfaceRegistry([root, *InterfaceRegistry().roots])


@pytest.fixture(scope="module")
def registry() -> InterfaceRegistry:
    return InterfaceRegistry()


@pytest.mark.parametrize("ros_type", sorted(JAZZY_HASHES))
def test_type_hashes_are_those_of_jazzy(registry: InterfaceRegistry, ros_type: str) -> None:
    assert type_hash(registry, ros_type) == JAZZY_HASHES[ros_type]


def test_cdr_is_what_rmw_cyclonedds_writes(registry: InterfaceRegistry) -> None:
    string = registry.message("std_msgs/msg/String")
    assert string.__idl_typename__ == "std_msgs::msg::dds_::String_"
    # encapsulation CDR_LE (XCDR1), length 3 with the terminating NUL
    assert string(data="hi").serialize() == b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00"
    request, _ = registry.wire_service("std_srvs/srv/Trigger")
    # rmw_cyclonedds_cpp's header (uint64 client id, int64 sequence), then rosidl's placeholder octet
    sample = request(guid=0x0102030405060708, seq=7, structure_needs_at_least_one_member=0)
    assert sample.serialize() == b"\x00\x01\x00\x00" + bytes(range(8, 0, -1)) + (7).to_bytes(8, "little") + b"\x00"
    point = registry.message("geometry_msgs/msg/Point")
    stamped = registry.message("builtin_interfaces/msg/Time")
    assert len(stamped(sec=1, nanosec=2).serialize()) == 4 + 8
    assert len(point(x=1.0, y=2.0, z=3.0).serialize()) == 4 + 24


def test_type_names_follow_rosidl(registry: InterfaceRegistry) -> None:
    assert dds_type_name("sensor_msgs/msg/JointState") == "sensor_msgs::msg::dds_::JointState_"
    request, reply = registry.wire_service("std_srvs/srv/Trigger")
    assert request.__idl_typename__ == "std_srvs::srv::dds_::Trigger_Request_"
    assert reply.__idl_typename__ == "std_srvs::srv::dds_::Trigger_Response_"
    action = registry.wire_action("dual_arm_executive_interfaces/action/RunApplication")
    assert action["SendGoal_Request"].__idl_typename__ == "dual_arm_executive_interfaces::action::dds_::RunApplication_SendGoal_Request_"
    assert action["FeedbackMessage"].__idl_typename__ == "dual_arm_executive_interfaces::action::dds_::RunApplication_FeedbackMessage_"


@pytest.mark.parametrize("mirror", [*msgs.MESSAGE_TYPES, msgs.ClockMessage])
def test_every_mirror_matches_its_interface_file(mirror: type) -> None:
    converter = DdsConverter(InterfaceRegistry())
    cls = converter.wire_class(mirror)
    assert [f.name for f in dataclasses.fields(mirror)] == list(cls.__annotations__)


def test_a_mirror_with_a_field_its_file_lacks_is_refused() -> None:
    @dataclasses.dataclass(frozen=True)
    class Wrong:
        ROS_TYPE = "std_msgs/msg/String"
        data: str = ""
        extra: int = 0

    with pytest.raises(Exception, match="extra"):
        DdsConverter(InterfaceRegistry()).wire_class(Wrong)


def test_mirrors_round_trip_through_cdr() -> None:
    converter = DdsConverter(InterfaceRegistry())
    stamp = msgs.Header(msgs.Time(1_700_000_000, 5), "world")
    samples = [
        msgs.JointState(stamp, ("a", "b"), (0.25, -1.5), (0.0, 0.1), ()),
        msgs.DiagnosticArray(stamp, (msgs.DiagnosticStatus(level=b"\x02", name="left_arm", values=(msgs.KeyValue("k", "v"),)),)),
        msgs.TFMessage((msgs.TransformStamped(stamp, "tool0", msgs.Transform(msgs.Vector3(1, 2, 3), msgs.Quaternion(0, 0, 0, 1))),)),
        msgs.String("<robot name='x'/>"),
    ]
    for msg in samples:
        cls = converter.wire_class(type(msg))
        data = converter.to_wire(msg).serialize()
        assert converter.from_wire(type(msg), cls.deserialize(data)) == msg


def test_truncated_cdr_does_not_decode(registry: InterfaceRegistry) -> None:
    cls = registry.message("sensor_msgs/msg/JointState")
    data = DdsConverter(registry).to_wire(msgs.JointState(name=("a",), position=(1.0,))).serialize()
    with pytest.raises(Exception):
        cls.deserialize(data[: len(data) // 2])


# ------------------------------------------------------------------------ the project's package
WIRE_TO_MSG = {
    wire.EngineStatus: ("EngineStatus", {"t": "header", "v": None, "operation_id": "operation_id"}),
    wire.SmStatus: ("MachineStatus", {"t": "header", "v": None, "result": "result_json"}),
    wire.SmStructure: ("MachineStructure", {"v": None}),
    wire.SmRequest: ("MachineRequest", {"v": None}),
    wire.SmResult: ("MachineResult", {"v": None, "t_start": "start", "t_end": "header"}),
    wire.BridgeCommand: ("BridgeCommand", {"v": None, "primitive": "primitive_json"}),
    wire.BridgeFeedback: ("BridgeFeedback", {"t": "header", "v": None, "result": "result_json"}),
    wire.SyncMessage: ("SyncMessage", {"t": "header", "v": None}),
    wire.CellSnapshot: ("CellSnapshot", {"v": None, "joint_pose_groups": "joint_poses"}),
    wire.LocatedFrames: ("LocatedFrames", {"t": "header", "v": None}),
    wire.GroupProgress: ("GroupProgress", {}),
    wire.TransitionSpec: ("MachineTransition", {}),
}


@pytest.mark.parametrize("dataclass_type", list(WIRE_TO_MSG), ids=lambda t: t.__name__)
def test_each_wire_message_has_its_typed_interface(registry: InterfaceRegistry, dataclass_type: type) -> None:
    """Field by field: every field of the JSON message has a field in the .msg (renamed where a
    JSON payload or a stamp takes its place), so nothing is lost when the typed form is used."""
    name, renames = WIRE_TO_MSG[dataclass_type]
    declared = {f.name for f in registry.spec(f"dual_arm_executive_interfaces/msg/{name}").fields}
    for f in dataclasses.fields(dataclass_type):
        target = renames.get(f.name, f.name)
        if target is not None:
            assert target in declared, f"{name}.msg lacks {target} for {dataclass_type.__name__}.{f.name}"


def test_package_lists_every_interface_file() -> None:
    cmake = (PACKAGE / "CMakeLists.txt").read_text()
    files = sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*") if p.suffix in (".msg", ".srv", ".action"))
    assert files and all(f'"{f}"' in cmake for f in files)


def test_every_project_interface_builds(registry: InterfaceRegistry) -> None:
    for path in sorted((PACKAGE / "msg").glob("*.msg")):
        assert registry.message(f"dual_arm_executive_interfaces/msg/{path.stem}")
    registry.wire_service("dual_arm_executive_interfaces/srv/OperatorCommand")
    goal = registry.spec("dual_arm_executive_interfaces/action/RunApplication_Goal")
    assert [f.name for f in goal.fields] == ["application_file", "application_xml", "backend", "speed"]


# ------------------------------------------------------------------------------------ parser
def test_parser_names_file_and_line() -> None:
    with pytest.raises(InterfaceError, match=r"x.msg:2: cannot parse"):
        parse_message("int32 a\nint32[ b\n", "p/msg/X", "x.msg")
    with pytest.raises(InterfaceError, match="wstring"):
        parse_message("wstring a", "p/msg/X", "x.msg")


def test_parser_reads_constants_defaults_bounds() -> None:
    spec = parse_message("byte OK=0\nstring<=8 NAME='a b'\nfloat64 x 1.5\nint8[<=3] v\nuint8[4] u\nHeader h\nOther o", "p/msg/X")
    assert [c.name for c in spec.constants] == ["OK", "NAME"]
    assert [(f.name, f.base, f.array, f.default) for f in spec.fields] == [
        ("x", "float64", None, "1.5"), ("v", "int8", "<=3", None), ("u", "uint8", "4", None),
        ("h", "std_msgs/msg/Header", None, None), ("o", "p/msg/Other", None, None),
    ]


@given(st.text(max_size=300))
def test_parser_never_fails_other_than_with_interface_error(text: str) -> None:
    try:
        parse_message(text, "p/msg/X")
    except InterfaceError:
        pass


JAZZY_ACTION_HASHES = {
    "tf2_msgs/action/LookupTransform_Goal": "RIHS01_815efc294ad17c813c6043cdde781ff55810d49da02ed07f9237dcd20e88d498",
    "tf2_msgs/action/LookupTransform_Result": "RIHS01_061d4423af5352ff5314c8effef8faab133991a78f1b2bcd1fecabad80871225",
    "tf2_msgs/action/LookupTransform_Feedback": "RIHS01_2da0b02f990f04404ab8c98a2a68cf5bbc773ae747f96911f2d55499cfb51542",
    "tf2_msgs/action/LookupTransform_SendGoal_Request": "RIHS01_eb1312eb7aab35e35c71bb87c2ba3a94747c5a6544ea32bb2b32b0f75775b8ca",
    "tf2_msgs/action/LookupTransform_SendGoal_Response": "RIHS01_c1ada93304793c08813657255e7bde2e40e2114aa634b702c3f8d4b72ae098bc",
    "tf2_msgs/action/LookupTransform_GetResult_Request": "RIHS01_148f9bdc01f98922d6fb2072cb64468b89c57c7825d9d83b932c183deaa4697d",
    "tf2_msgs/action/LookupTransform_GetResult_Response": "RIHS01_954de3efc36b164c4d21116abdbdcc52746e454fd9c169b55d9cfd89e83d299d",
    "tf2_msgs/action/LookupTransform_FeedbackMessage": "RIHS01_10cb89922dcb103e95c185d43e8a5efa3d38db996f733151a2f3e2ac133f4839",
}


@pytest.mark.parametrize("ros_type", sorted(JAZZY_ACTION_HASHES))
def test_action_type_hashes_are_those_of_jazzy(action_registry: InterfaceRegistry, ros_type: str) -> None:
    assert type_hash(action_registry, ros_type) == JAZZY_ACTION_HASHES[ros_type]


def test_action_requests_round_trip_with_the_request_header(registry: InterfaceRegistry) -> None:
    """A RunApplication goal as `ros2 action send_goal` writes it: header, 16-octet goal id, goal."""
    converter = DdsConverter(registry)
    request_type, _ = registry.wire_service(SendGoal.ROS_TYPE)
    request = SendGoal.Request(UUID(tuple(range(16))), RunApplicationGoal("/apps/rivet.xml", "", "nextage-sim", 0.0))
    sample = request_type.deserialize(converter.to_wire_service(request_type, request, 7, 3).serialize())
    assert (sample.guid, sample.seq) == (7, 3)
    assert converter.from_wire(SendGoal.Request, sample) == request


def test_mirrors_generated_from_the_files_use_the_written_ones_where_they_exist() -> None:
    assert mirrors.mirror("builtin_interfaces/msg/Time") is msgs.Time
    status = mirrors.mirror("action_msgs/msg/GoalStatus")
    assert status.STATUS_CANCELED == 5 and status().goal_info.stamp == msgs.Time()
    assert mirrors.mirror("unique_identifier_msgs/msg/UUID")().uuid == (0,) * 16
    assert mirrors.mirror("diagnostic_msgs/msg/DiagnosticStatus") is msgs.DiagnosticStatus
    goal = mirrors.action("dual_arm_executive_interfaces/action/RunApplication").Goal
    assert [f.name for f in dataclasses.fields(goal)] == ["application_file", "application_xml", "backend", "speed"]
    assert goal().speed == 0.0
