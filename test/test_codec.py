"""The JSON contract: every wire message round-trips, and garbage is refused with a clear, located error."""
from __future__ import annotations

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from core_functions.geometry import Pose
from core_functions.primitives import Dwell, EndEffector, MasterSlaveMove, MotionResult, MoveCartesian, MoveJoints, SetSpeed, Vision, VisionResult
from node_transport import codec
from node_transport.wire import (
    BridgeCommand,
    BridgeFeedback,
    CellSnapshot,
    EngineEvent,
    EngineStatus,
    FaultKind,
    GroupProgress,
    SmRequest,
    SmResult,
    SmStatus,
    SmStructure,
    SyncMessage,
    TransitionSpec,
)
from core_functions.cell_index import CellFrame

POSE = Pose.from_xyz_rpy(0.3, -0.1, 0.2, 0.1, 1.2, -0.4)

MESSAGES = [
    SmRequest(id="r1", operation="3", function="pick_rivet", params=("rivet_1", "ref_R10"), sync="k", partners=("left_arm", "right_arm")),
    SmRequest(id="r2", kind="end"),
    SmResult(id="r1", group="right_arm", outcome="aborted", operation="3", function="pick_rivet", error="unreachable", t_start=1.0, t_end=2.5, primitives=3),
    SmStatus(group="left_arm", event="transition", state="Motion", t=1.25, from_state="Ready", to_state="Motion", signal="motion_request"),
    SmStructure(group="g", initial="Ready", states=("Ready", "Motion"), transitions=(TransitionSpec("Ready", "motion_request", "Motion"),)),
    BridgeCommand(id="c1", group="left_arm", op="execute", primitive=MoveCartesian(POSE, "linear", "drill_1")),
    BridgeCommand(id="c2", group="left_arm", op="execute", primitive=MasterSlaveMove("left_arm", "right_arm", (POSE,), None)),
    BridgeCommand(id="c3", group="left_arm", op="pause"),
    BridgeFeedback(id="c1", group="left_arm", status="done", result=MotionResult(("LARM_JOINT0",), (0.1,), POSE), t=3.0),
    BridgeFeedback(id="c4", group="left_arm", status="done", result=VisionResult(POSE, 0.25, 0.9), t=3.5),
    EngineStatus(app="a", state="running", operation_index=2, operation_count=9, t=4.0, groups={"left_arm": GroupProgress("Motion", "2", "debur_drilling")}),
    CellSnapshot(name="c", frames=(CellFrame("drill_1", POSE, "hole", "part", {"diameter": "0.0048"}),), truth={"drill_1": POSE}),
    SyncMessage(group="left_arm", key="k", event="arrived", state="FullBodyMotion", t=1.0),
    BridgeFeedback(id="c5", group="left_arm", status="error", error="joint_limit: LARM_JOINT1", fault=FaultKind.JOINT_LIMIT, t=4.0),
    EngineEvent(event="operator", t=5.0, state="alarm", operation="3", command="reset", source="terminal console (key 'x')", accepted=True, answer="retrying"),
]


@pytest.mark.parametrize("message", MESSAGES, ids=lambda m: type(m).__name__)
def test_every_message_round_trips(message: object) -> None:
    text = codec.encode(message)
    assert codec.decode(type(message), text) == message
    assert json.loads(text)["v"] == 1


def test_keyword_fields_use_their_json_names() -> None:
    raw = json.loads(codec.encode(MESSAGES[3]))
    assert raw["from"] == "Ready" and raw["to"] == "Motion" and "from_state" not in raw


@pytest.mark.parametrize(
    ("cls", "text", "expected"),
    [
        (BridgeCommand, '{"id":"1","group":"g","op":"execute"}', "an execute command carries a primitive"),
        (BridgeCommand, '{"id":"1","group":"g","op":"jump"}', "field 'op': 'jump' is not one of 'execute', 'pause', 'resume', 'stop'"),
        (BridgeCommand, '{"id":"1","group":"g","op":"execute","primitive":{"kind":"set_speed","fraction":"fast"}}', "field 'primitive.fraction': expected a finite number"),
        (BridgeCommand, '{"id":"1","group":"g","op":"execute","primitive":{"kind":"move_joints","positions":[1,"x"]}}', "field 'primitive.positions[1]'"),
        (BridgeCommand, '{"id":"1","group":"g","op":"execute","primitive":{"kind":"teleport"}}', "field 'primitive.kind': 'teleport' is not one of"),
        (SmResult, '{"id":"1","group":"g","outcome":"succeeded","extra":1}', "field 'extra': unknown field in SmResult"),
        (SmResult, '{"id":"1","outcome":"succeeded"}', "field 'group': is required"),
        (SmRequest, '{"id":"1","function":"f","v":2}', "protocol version 2 is not supported"),
        (SmRequest, '[1,2]', "expected an object for SmRequest"),
        (SmRequest, '{"id":"1","function":"f","params":[NaN]}', "not valid JSON"),
        (BridgeFeedback, '{"id":"1","group":"g","status":"done","t":1e999}', "infinity"),
    ],
)
def test_garbage_is_refused_naming_the_message_and_field(cls: type, text: str, expected: str) -> None:
    with pytest.raises(codec.WireError) as error:
        codec.decode(cls, text, source="/left_arm/bridge/command")
    assert expected in str(error.value)
    assert "from /left_arm/bridge/command" in str(error.value)


def test_size_limit_is_checked_before_parsing() -> None:
    with pytest.raises(codec.WireError, match="exceeds the limit of 100"):
        codec.decode(SmRequest, '{"id":"' + "x" * 200 + '"}', max_bytes=100)


def test_non_finite_numbers_cannot_be_sent() -> None:
    with pytest.raises(codec.WireError, match="non-finite"):
        codec.encode(BridgeFeedback(id="1", group="g", status="done", t=math.inf))


@given(st.text(max_size=300))
def test_random_text_never_escapes_as_anything_but_wire_error(text: str) -> None:
    for cls in (SmRequest, BridgeCommand, BridgeFeedback, SmStatus, CellSnapshot):
        try:
            codec.decode(cls, text)
        except codec.WireError:
            pass


@given(st.integers(min_value=0, max_value=10_000), st.sampled_from(MESSAGES))
def test_every_truncation_of_a_valid_message_is_refused_cleanly(cut: int, message: object) -> None:
    text = codec.encode(message)
    truncated = text[: cut % max(1, len(text))]
    with pytest.raises(codec.WireError):
        codec.decode(type(message), truncated)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=10),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4),
    max_leaves=20,
)


@given(st.dictionaries(st.sampled_from(["id", "group", "op", "primitive", "kind", "v", "positions", "x"]), json_values, max_size=6))
def test_random_json_objects_are_validated_not_trusted(raw: dict[str, object]) -> None:
    try:
        command = codec.from_primitive(BridgeCommand, raw)
    except codec.WireError:
        return
    assert isinstance(command.id, str) and command.op in ("execute", "pause", "resume", "stop")


@given(
    st.lists(st.floats(-3.0, 3.0), min_size=1, max_size=15),
    st.sampled_from(["gripper_open", "tool_on", "hand_keep"]),
    st.floats(0.01, 1.0),
    st.floats(0.0, 100.0),
)
def test_primitives_round_trip(positions: list[float], action: str, fraction: float, seconds: float) -> None:
    for primitive in (MoveJoints(tuple(positions)), EndEffector(action), SetSpeed(fraction), Dwell(seconds), Vision("locate", "drill_1", POSE, "cam")):  # type: ignore[arg-type]
        command = BridgeCommand(id="x", group="g", op="execute", primitive=primitive)
        assert codec.decode(BridgeCommand, codec.encode(command)) == command


@pytest.mark.parametrize("text", ['{"id":"1","v":1e999}', '{"id":"1","v":NaN}', '{"id":"1","v":-Infinity}', '{"id":"1",}', "{"])
def test_both_json_back_ends_refuse_what_is_not_finite_json(text: str) -> None:
    """orjson when installed, the standard library otherwise: the same messages are refused."""
    for loads in (codec.loads_std, codec.loads):
        with pytest.raises(ValueError):
            loads(text)
    assert json.loads(codec.dumps_std({"a": [1.5, "x", None]})) == json.loads(codec.dumps({"a": [1.5, "x", None]}))
