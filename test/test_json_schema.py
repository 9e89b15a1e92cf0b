"""The JSON Schemas under schema/json: current, valid draft 2020-12, and judging messages as the decoder does."""
from __future__ import annotations

import copy
import dataclasses
import enum
import functools
import inspect
import json
import math
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin

import pytest
from hypothesis import given
from hypothesis import strategies as st
from jsonschema import Draft202012Validator
from test_codec import MESSAGES, POSE, json_values

from core_functions import primitives as prim
from core_functions.geometry import Pose
from node_transport import codec, json_schema, wire

SCHEMA_DIR = Path(__file__).resolve().parents[1] / "schema" / "json"
TYPES = json_schema.message_types()

PRIMITIVES = (
    prim.MoveJoints((0.1, -0.2), ("j1", "j2"), relative=True),
    prim.MoveCartesian(POSE, "linear", "drill_1"),
    prim.MoveRelative(Pose(z=0.01), "tool"),
    prim.SetSpeed(0.5),
    prim.Dwell(1.5),
    prim.EndEffector("gripper_close"),
    prim.Vision("locate", "drill_1", POSE, "cam"),
    prim.RecordTrajectory("path", "teach", duration=2.0, sample_period=0.05),
    prim.ExecuteTrajectory("path", ("j1",), ((0.0,), (0.5,)), (0.0, 1.0)),
    prim.FullBodyMove(("j1", "j2"), (0.0, 1.0)),
    prim.MasterSlaveMove("left_arm", "right_arm", (POSE,), POSE),
    prim.SetOutput("GPIO.01", 1.0),
    prim.WaitInput("Tech.C11", 2.5, timeout=3.0, tolerance=0.1),
)
RESULTS = (
    prim.MotionResult(("j1",), (0.3,), POSE),
    prim.EndEffectorResult({"valve": True}),
    prim.VisionResult(None, 0.002, 0.75),
    prim.TrajectoryResult(("j1",), ((0.0,), (0.1,)), (0.0, 0.5)),
    prim.IoResult({"GPIO.01": 1.0, "Tech.C11": 2.5}),
)
EXAMPLES = (
    *MESSAGES,
    wire.LocatedFrames(group="left_arm", cell="c", frames={"drill_1": POSE}, t=5.0),
    *(wire.BridgeCommand(id=f"c{i}", group="left_arm", op="execute", primitive=p) for i, p in enumerate(PRIMITIVES)),
    *(wire.BridgeFeedback(id=f"c{i}", group="left_arm", status="done", result=r, t=2.0) for i, r in enumerate(RESULTS)),
)


def inner_type(message: object) -> type:
    """The type of a command's primitive or a feedback's result (NoneType for other messages)."""
    return type(getattr(message, "primitive", None) or getattr(message, "result", None))


def name_of(message: object) -> str:
    return type(message).__name__ + (f"-{inner_type(message).__name__}" if dataclasses.is_dataclass(inner_type(message)) else "")


@functools.cache
def validator(cls: type) -> Draft202012Validator:
    """The validator of the committed (installed) schema file, not of a fresh generation."""
    path = SCHEMA_DIR / json_schema.file_name(cls)
    assert path.is_file(), f"{path} is missing; regenerate with `{json_schema.REGENERATE}`"
    return Draft202012Validator(json.loads(path.read_text(encoding="utf-8")))


def encoded(message: object) -> Any:
    return json.loads(codec.encode(message))


# ------------------------------------------------------------------------- (a) up to date
def test_committed_schemas_are_what_the_generator_writes_now() -> None:
    stale = [p.name for p in json_schema.stale(SCHEMA_DIR)]
    assert stale == [], f"stale files in schema/json: {stale}; regenerate with `{json_schema.REGENERATE}`"


def test_check_names_each_stale_file_and_out_repairs_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert json_schema.main(["--out", str(tmp_path)]) == 0
    assert json_schema.main(["--check", str(tmp_path)]) == 0
    (tmp_path / "SmResult.schema.json").write_text("{}", encoding="utf-8")
    (tmp_path / "Retired.schema.json").write_text("{}", encoding="utf-8")
    (tmp_path / "index.json").unlink()
    capsys.readouterr()
    assert json_schema.main(["--check", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert {line.removeprefix("stale: ") for line in err.splitlines() if line.startswith("stale: ")} == {
        str(tmp_path / n) for n in ("SmResult.schema.json", "Retired.schema.json", "index.json")
    }
    assert json_schema.REGENERATE in err
    assert json_schema.main(["--out", str(tmp_path)]) == 0
    assert json_schema.main(["--check", str(tmp_path)]) == 0
    assert not (tmp_path / "Retired.schema.json").exists()


def test_every_message_of_wire_py_is_registered() -> None:
    """A top-level message is a wire.py dataclass with the protocol version ``v``; each needs its schema."""
    top_level = {
        cls for cls in vars(wire).values()
        if isinstance(cls, type) and dataclasses.is_dataclass(cls) and cls.__module__ == wire.__name__
        and any(f.name == json_schema.VERSION for f in dataclasses.fields(cls))
    }
    assert top_level == set(TYPES), "add the new message with its topic to json_schema.MESSAGES"


def test_index_maps_relative_topics_to_message_types_and_files() -> None:
    index = json.loads((SCHEMA_DIR / json_schema.INDEX).read_text(encoding="utf-8"))
    assert index["topics"]["<group>/sm/request"] == "SmRequest"
    assert index["topics"]["<group>/bridge/feedback"] == "BridgeFeedback"
    assert index["topics"][wire.ENGINE_CELL] == "CellSnapshot"
    assert set(index["topics"].values()) == set(index["schemas"]) == {cls.__name__ for cls in TYPES}
    assert not [topic for topic in index["topics"] if topic.startswith("/")]
    assert all((SCHEMA_DIR / file).is_file() for file in index["schemas"].values())


# ----------------------------------------------------------------- (b) valid draft 2020-12
def refs(node: Any) -> list[str]:
    if isinstance(node, dict):
        return [v for k, v in node.items() if k == "$ref"] + [r for v in node.values() for r in refs(v)]
    return [r for v in node for r in refs(v)] if isinstance(node, list) else []


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_every_schema_is_a_valid_draft_2020_12_schema(cls: type) -> None:
    schema = validator(cls).schema
    Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["$id"].endswith(f"/{cls.__name__}.schema.json")
    assert (schema["title"], schema["description"]) == (cls.__name__, inspect.getdoc(cls))
    dangling = [r for r in refs(schema) if r != "#" and r.removeprefix("#/$defs/") not in schema.get("$defs", {})]
    assert dangling == []


# ------------------------------------------------------------- (c) real messages validate
def test_the_examples_cover_every_message_primitive_and_result() -> None:
    assert {type(m) for m in EXAMPLES} == set(TYPES), "add an example of the new message"
    assert {type(p) for p in PRIMITIVES} == set(get_args(prim.Primitive)), "add an example of the new primitive"
    assert {type(r) for r in RESULTS} == set(get_args(prim.PrimitiveResult)), "add an example of the new result"


@pytest.mark.parametrize("message", EXAMPLES, ids=name_of)
def test_encoded_messages_validate(message: object) -> None:
    errors = [e.message for e in validator(type(message)).iter_errors(encoded(message))]
    assert errors == []


FLOATS = st.floats(-1e6, 1e6)
TEXT = st.text(max_size=6)
ANGLE = st.floats(-math.pi, math.pi)


def _trajectory(joints: int, points: int) -> st.SearchStrategy[prim.ExecuteTrajectory]:
    return st.builds(
        prim.ExecuteTrajectory, TEXT, st.tuples(*[TEXT] * joints),
        st.tuples(*[st.tuples(*[FLOATS] * joints)] * points), st.tuples(*[st.floats(0, 100)] * points).map(lambda t: tuple(sorted(t))),
    )


# Where __post_init__ ties fields together, random fields would almost never make a valid message.
OVERRIDES: dict[Any, st.SearchStrategy[Any]] = {
    Pose: st.builds(Pose.from_xyz_rpy, FLOATS, FLOATS, FLOATS, ANGLE, ANGLE, ANGLE),
    prim.SetSpeed: st.builds(prim.SetSpeed, st.floats(0.0, 1.0, exclude_min=True)),
    prim.ExecuteTrajectory: st.tuples(st.integers(0, 3), st.integers(1, 3)).flatmap(lambda n: _trajectory(*n)),
}


def _make(cls: type, kwargs: dict[str, Any]) -> Any:
    try:
        return cls(**kwargs)
    except (TypeError, ValueError):  # refused by the dataclass's own checks
        return None


def _integers(value: Any) -> list[int]:
    if isinstance(value, (list, dict)):
        return [i for v in (value.values() if isinstance(value, dict) else value) for i in _integers(v)]
    return [value] if type(value) is int else []


def instances(hint: Any) -> st.SearchStrategy[Any]:  # noqa: C901 - one case per type form codec supports
    """Any value of ``hint`` the encoder can send, built from the type hints (independently of the generator)."""
    if hint in OVERRIDES:
        return OVERRIDES[hint]
    if hint is Any:  # within 64 bits: orjson cannot write a larger integer (codec lets its TypeError out)
        return json_values.filter(lambda v: all(-(2**63) <= i < 2**64 for i in _integers(v)))
    if dataclasses.is_dataclass(hint):
        hints = typing.get_type_hints(hint)
        # v stays the protocol version: the schema holds every message to it (see docs/json_messages.md)
        fields = {f.name: instances(hints[f.name]) for f in dataclasses.fields(hint) if f.init and f.name != "v"}
        return st.fixed_dictionaries(fields).map(functools.partial(_make, hint)).filter(lambda m: m is not None)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return st.sampled_from(hint)
    origin, args = get_origin(hint), get_args(hint)
    if origin is Literal:
        return st.sampled_from(args)
    if origin in (Union, types.UnionType):
        return st.one_of([instances(a) for a in args])
    if origin is tuple and args and args[-1] is not Ellipsis:
        return st.tuples(*[instances(a) for a in args])
    if origin in (list, tuple):
        return st.lists(instances(args[0]), max_size=3).map(origin)
    if origin is dict:
        return st.dictionaries(TEXT, instances(args[1]), max_size=3)
    scalars = {bool: st.booleans(), int: st.integers(-(2**63), 2**63 - 1), float: FLOATS, str: TEXT, type(None): st.none()}
    return scalars[hint]


@given(st.sampled_from(TYPES).flatmap(instances))
def test_any_message_the_encoder_sends_validates(message: object) -> None:
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in validator(type(message)).iter_errors(encoded(message))]
    assert errors == []


# ------------------------------------------------ (d) what the decoder refuses, the schema refuses
DELETE = object()
# Reasons codec gives for a structural mismatch; anything else comes from a dataclass's __post_init__,
# which a schema does not express (a unit quaternion, an execute command with its primitive).
STRUCTURAL = re.compile(r"^(is required|expected |unknown field in )| is not one of ")


def mutated(raw: Any, path: tuple[str | int, ...], value: Any) -> Any:
    """A copy of ``raw`` with the value at ``path`` replaced (or added), or removed for ``DELETE``."""
    out = copy.deepcopy(raw)
    node = out
    for part in path[:-1]:
        node = node[part]
    if value is not DELETE:
        node[path[-1]] = value
    elif isinstance(node, dict):
        node.pop(path[-1], None)
    else:
        del node[path[-1]]
    return out


def by_type(cls: type, inner: type | None = None) -> Any:
    """The first example of ``cls`` (carrying an ``inner`` primitive or result), as JSON values."""
    return next(encoded(m) for m in EXAMPLES if type(m) is cls and inner in (None, inner_type(m)))


CASES = [
    ("missing required field", wire.SmResult, None, ("group",), DELETE),
    ("missing required nested field", wire.SmStructure, None, ("transitions", 0, "to"), DELETE),
    ("missing required primitive field", wire.BridgeCommand, prim.MoveJoints, ("primitive", "positions"), DELETE),
    ("wrong literal", wire.SmRequest, None, ("kind",), "begin"),
    ("literal in another case", wire.SyncMessage, None, ("event",), "ARRIVED"),
    ("wrong literal in a primitive", wire.BridgeCommand, prim.MoveCartesian, ("primitive", "interpolation"), "spline"),
    ("unknown primitive tag", wire.BridgeCommand, None, ("primitive", "kind"), "teleport"),
    ("primitive without its tag", wire.BridgeCommand, None, ("primitive", "kind"), DELETE),
    ("tag of another primitive", wire.BridgeCommand, prim.MoveJoints, ("primitive", "kind"), "dwell"),
    ("unknown result tag", wire.BridgeFeedback, None, ("result", "kind"), "sound"),
    ("string for a number", wire.SmStatus, None, ("t",), "soon"),
    ("bool for a number", wire.BridgeFeedback, None, ("t",), True),
    ("fraction for an integer", wire.SmResult, None, ("primitives",), 2.5),
    ("bool for an integer", wire.EngineStatus, None, ("operation_index",), True),
    ("number for a string", wire.SmResult, None, ("id",), 7),
    ("null for a required string", wire.SmResult, None, ("group",), None),
    ("string for a list", wire.SmStructure, None, ("states",), "Ready"),
    ("wrong list item", wire.BridgeCommand, prim.MoveJoints, ("primitive", "positions", 0), "x"),
    ("wrong dict value", wire.CellSnapshot, None, ("joint_poses",), {"home": {"j1": "zero"}}),
    ("wrong pose component", wire.CellSnapshot, None, ("frames", 0, "pose", "qw"), "1"),
    ("wrong result map value", wire.BridgeFeedback, prim.EndEffectorResult, ("result", "io", "valve"), "on"),
    ("list for an object", wire.EngineStatus, None, ("groups", "left_arm"), ["Motion"]),
    ("list for a free-form object", wire.SmStatus, None, ("result",), [1]),
    ("Python name of a renamed field", wire.SmStatus, None, ("from_state",), "Ready"),
    ("unknown key", wire.SmResult, None, ("extra",), 1),
    ("unknown key in a nested object", wire.EngineStatus, None, ("groups", "left_arm", "extra"), 1),
    ("unknown key in a primitive", wire.BridgeCommand, None, ("primitive", "speed"), 0.5),
    ("other protocol version", wire.SmRequest, None, ("v",), 2),
]


@pytest.mark.parametrize(("cls", "inner", "path", "value"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_what_the_decoder_refuses_the_schema_refuses(cls: type, inner: type | None, path: tuple[str | int, ...], value: Any) -> None:
    raw = by_type(cls, inner)
    assert validator(cls).is_valid(raw) and codec.decode(cls, json.dumps(raw)) is not None  # the change is what fails
    bad = mutated(raw, path, value)
    with pytest.raises(codec.WireError):
        codec.decode(cls, json.dumps(bad))
    assert not validator(cls).is_valid(bad)


def assert_judged_alike(cls: type, raw: Any, *, version_changed: bool = False) -> None:
    """A structural refusal of the decoder is a refusal of the schema, and what it accepts the schema accepts."""
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in validator(cls).iter_errors(raw)]
    try:
        codec.from_primitive(cls, raw)
    except codec.WireError as error:
        if STRUCTURAL.search(error.reason):
            assert errors, f"the decoder refuses ({error}) but the schema accepts {raw}"
        return
    # the schema holds every message to protocol version 1; not every __post_init__ checks it
    assert errors == [] or version_changed, f"the decoder accepts {raw} but the schema refuses: {errors}"


def paths(node: Any, prefix: tuple[str | int, ...] = ()) -> list[tuple[str | int, ...]]:
    """Every place in a JSON value, plus a new key in every object."""
    if isinstance(node, dict):
        children = [p for k, v in node.items() for p in paths(v, (*prefix, k))]
        return [*([prefix] if prefix else []), (*prefix, "unknown"), *children]
    if isinstance(node, list):
        return [*([prefix] if prefix else []), *(p for i, v in enumerate(node) for p in paths(v, (*prefix, i)))]
    return [prefix]


@pytest.mark.parametrize("message", EXAMPLES, ids=name_of)
def test_a_key_is_required_by_the_schema_exactly_when_the_decoder_requires_it(message: object) -> None:
    raw = encoded(message)
    for path in paths(raw):
        assert_judged_alike(type(message), mutated(raw, path, DELETE))


def _fractional(value: Any) -> Any:
    """JSON Schema counts 1.0 as an integer, the decoder does not (documented); keep such floats out."""
    if isinstance(value, float) and value.is_integer():
        return value + 0.5 if abs(value) < 2**52 else 0.5
    if isinstance(value, list):
        return [_fractional(v) for v in value]
    return {k: _fractional(v) for k, v in value.items()} if isinstance(value, dict) else value


@given(st.data())
def test_changed_messages_are_judged_alike_by_decoder_and_schema(data: st.DataObject) -> None:
    message = data.draw(st.sampled_from(TYPES).flatmap(instances))
    raw = encoded(message)
    path = data.draw(st.sampled_from(paths(raw)))
    value = data.draw(st.just(DELETE) | json_values.map(_fractional) | st.sampled_from(["execute", "motion", "dwell", None, 0, 1]))
    assert_judged_alike(type(message), mutated(raw, path, value), version_changed=path == (json_schema.VERSION,))
