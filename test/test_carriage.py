"""In one process a message crosses the transport once, and the receiver gets what the wire would give it.

What a user relies on: a node receives the same types and values, validated the same way, whether
its peer runs in its process (the embedded run, the tests) or in another one over rclpy or DDS;
nothing a receiver does to what it got reaches another receiver or the sender; the local transport
keeps its ROS 2 semantics (asynchronous delivery, KEEP_LAST, TRANSIENT_LOCAL) for objects too.
"""
from __future__ import annotations

import asyncio
import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scripted_backend import Executed, ScriptedBackend

from core_functions.geometry import Pose
from core_functions.primitives import (
    EndEffector,
    EndEffectorResult,
    ExecuteTrajectory,
    MotionResult,
    MoveCartesian,
    MoveJoints,
    SetSpeed,
    VisionReport,
    VisionResult,
)
from cell_runner.libraries import APPLICATION_FUNCTIONS
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.engine.group_link import GroupLink
from execution_engine.machine.group_machine import GroupMachine
from node_transport import codec, typed
from node_transport.carriage import TypedPublisher, carriable, subscribe
from node_transport.clock import Clock
from node_transport.exact import copier
from node_transport.local import LocalTransport
from node_transport.qos import COMMANDS, LATCHED, QoS
from robot_bridges.bridge_node import BridgeNode
from node_transport.wire import (
    BridgeCommand,
    BridgeFeedback,
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

CLOCK = Clock(epoch=1_763_900_000.25)
TIMES = ("t", "t_start", "t_end")


# ------------------------------------------------------------------------ near misses
# Messages as nodes build them (clean), and with values the wire changes or refuses (noisy): "" for
# an optional text, -1 for an index, an int or a numpy number where a float belongs, a list for a
# tuple, NaN, a lone surrogate, an unknown literal, a protocol version the wire does not carry.
def _pick(clean: st.SearchStrategy[Any], *noise: st.SearchStrategy[Any], noisy: bool) -> st.SearchStrategy[Any]:
    """One value in eight a near miss, so that most noisy messages have one or two."""
    if not noisy:
        return clean
    return st.integers(0, 7).flatmap(lambda k: clean if k else st.one_of(*noise))


def _strategies(noisy: bool) -> st.SearchStrategy[Any]:  # noqa: C901 - one table of field strategies
    def texts() -> st.SearchStrategy[Any]:
        return _pick(st.one_of(st.none(), st.text(min_size=1, max_size=8)), st.just(""), st.just("\ud800"), st.integers(0, 2), noisy=noisy)

    def words() -> st.SearchStrategy[Any]:
        return _pick(st.text(max_size=8), st.just("\ud800x"), st.just(7), noisy=noisy)

    def floats(**bounds: Any) -> st.SearchStrategy[Any]:
        clean = st.floats(allow_nan=False, allow_infinity=False, **bounds)
        return _pick(clean, st.just(float("nan")), st.just(math.inf), st.integers(-5, 5), st.builds(np.float64, clean), noisy=noisy)

    def ints() -> st.SearchStrategy[Any]:
        return _pick(st.integers(0, 2**31), st.integers(-3, -1), st.integers(), st.just(True), st.just(1.0), noisy=noisy)

    def seq(item: st.SearchStrategy[Any], max_size: int = 4) -> st.SearchStrategy[Any]:
        return _pick(st.lists(item, max_size=max_size).map(tuple), st.lists(item, min_size=1, max_size=max_size), noisy=noisy)

    def maybe(item: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
        return st.one_of(st.none(), item)

    def literal(*values: str) -> st.SearchStrategy[Any]:
        return _pick(st.sampled_from(values), st.just("teleport"), noisy=noisy)

    leaves = _pick(st.one_of(st.none(), st.booleans(), st.integers(-(2**60), 2**60), floats(), st.text(max_size=6)),
                   st.integers(2**65, 2**70), st.just("\udfff"), noisy=noisy)
    json_values = st.recursive(leaves, lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=3),
        *([st.lists(inner, max_size=3).map(tuple), st.dictionaries(st.integers(0, 3), inner, min_size=1, max_size=2)] if noisy else []),
    ), max_leaves=8)
    poses = made(Pose, floats(min_value=-1, max_value=1), floats(min_value=-1, max_value=1), floats(min_value=-1, max_value=1))
    faults = maybe(st.sampled_from(FaultKind))
    primitives = st.one_of(
        made(SetSpeed, floats(min_value=0.01, max_value=1.0)),
        made(MoveJoints, seq(floats(min_value=-3, max_value=3))),
        made(MoveCartesian, poses, literal("ptp", "linear"), words()),
        made(EndEffector, literal("gripper_open", "air_on")),
        made(ExecuteTrajectory, words(), st.just(("a",)), st.just(((0.5,), (0.25,))), st.just((0.0, 1.0))),
    )
    results = st.one_of(
        made(MotionResult, seq(st.text(max_size=4)), seq(floats()), maybe(poses)),
        made(EndEffectorResult, st.dictionaries(words(), _pick(st.booleans(), st.integers(0, 1), noisy=noisy), max_size=3)),
        made(VisionResult, maybe(poses), maybe(floats()), floats(),
                  maybe(made(VisionReport, words(), words(), _pick(st.just((640, 480)), st.just([640, 480]), noisy=noisy)))),
        *([st.just({"kind": "motion"})] if noisy else []),
    )
    version = _pick(st.just(1), st.just(2), noisy=noisy)
    index = _pick(st.one_of(st.none(), st.integers(0, 2**31)), st.just(-1), st.just(True), noisy=noisy)
    return st.one_of(
        st.builds(built, st.just(SmRequest), words(), literal("execute", "end"), words(), st.text(min_size=1, max_size=6),
                  seq(words()), ints(), words(), seq(words()), words(), version),
        st.builds(built, st.just(SmResult), words(), words(), literal("succeeded", "aborted"), words(), words(), texts(),
                  faults, floats(), floats(), ints()),
        st.builds(built, st.just(SmStatus), words(), literal("transition", "primitive_end"), words(), floats(),
                  from_state=texts(), to_state=texts(), signal=texts(), operation=texts(), function=texts(), request_id=texts(),
                  primitive=texts(), index=index, count=index, outcome=texts(), error=texts(),
                  result=maybe(st.dictionaries(st.text(max_size=4), json_values, max_size=3)), v=version),
        st.builds(built, st.just(SmStructure), words(), words(), seq(words()), seq(st.builds(TransitionSpec, words(), words(), words()))),
        st.builds(built, st.just(BridgeCommand), words(), words(), literal("execute", "stop", "measure"), maybe(primitives)),
        st.builds(built, st.just(BridgeFeedback), words(), words(), literal("done", "error", "accepted"), texts(), faults,
                  maybe(results), floats()),
        st.builds(built, st.just(SyncMessage), words(), words(), literal("arrived", "failed"), words(), floats(), texts(), faults),
        st.one_of(  # accepted: a bool for an operator command, None otherwise
            st.builds(built, st.just(EngineEvent), st.just("operator"), floats(), words(), texts(), texts(), words(), texts(), texts(),
                      _pick(st.booleans(), st.none(), st.just(0), noisy=noisy), texts()),
            st.builds(built, st.just(EngineEvent), literal("state", "flag"), floats(), words(), texts(), texts(), words(), texts(),
                      texts(), _pick(st.none(), st.just(True), noisy=noisy), texts()),
        ),
        st.builds(built, st.just(EngineStatus), words(), literal("running", "paused"), ints(), ints(), floats(), texts(),
                  st.dictionaries(st.text(max_size=4), st.builds(GroupProgress, words(), texts(), texts()), max_size=2), words()),
    )


def built(cls: type, *args: Any, **kwargs: Any) -> Any:
    """The message, or None when its own constructor refuses it (the sender could not have sent it)."""
    try:
        return cls(*args, **kwargs)
    except (TypeError, ValueError):
        return None


def made(cls: type, *args: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """A part of a message (a pose, a primitive, a result) its constructor takes."""
    return st.builds(built, st.just(cls), *args).filter(lambda part: part is not None)


CLEAN, NOISY = _strategies(noisy=False), _strategies(noisy=True)


def the_long_way(obj: Any) -> Any:
    """What a receiver decoded before: the typed message and back (or the error of either side)."""
    try:
        msg = typed.to_msg(obj, CLOCK)
    except (codec.WireError, ValueError, TypeError, OverflowError) as error:
        return error
    try:
        return typed.from_msg(type(obj), msg, CLOCK, source="/topic")
    except codec.WireError as error:
        return error


def assert_same(got: Any, want: Any, path: str = "") -> None:
    """Equal and of the same types all the way down (a run time to within the wire's nanosecond)."""
    assert type(got) is type(want), f"{path}: {type(got).__name__} != {type(want).__name__}"
    if dataclasses.is_dataclass(got):
        for f in dataclasses.fields(got):
            a, b = getattr(got, f.name), getattr(want, f.name)
            if f.name in TIMES and not path:
                assert a == pytest.approx(b, abs=1e-9), f"{f.name}: {a} != {b}"
            else:
                assert_same(a, b, f"{path}.{f.name}")
    elif isinstance(got, (tuple, list)):
        assert len(got) == len(want), path
        for i, (a, b) in enumerate(zip(got, want)):
            assert_same(a, b, f"{path}[{i}]")
    elif isinstance(got, dict):
        assert list(got) == list(want), path
        for k in got:
            assert_same(got[k], want[k], f"{path}[{k!r}]")
    else:
        assert got == want, f"{path}: {got!r} != {want!r}"


@settings(max_examples=200, deadline=None)
@given(CLEAN)
def test_a_message_as_nodes_build_it_crosses_as_an_object_the_wire_would_deliver_the_same(obj: Any) -> None:
    assume(obj is not None)
    assert carriable(obj) is not None
    assert_same(obj, the_long_way(obj))
    assert_same(copier(type(obj))(obj), obj)  # what each receiver of its dicts and lists gets


@settings(max_examples=600, deadline=None)
@given(NOISY)
@example(SmStatus("left_arm", "primitive_end", "Motion", 1.0, index=-1))
@example(SmResult("r", "left_arm", "aborted", error=""))
@example(BridgeCommand("c", "left_arm", "execute", SetSpeed(1)))  # type: ignore[arg-type]
def test_whatever_crosses_as_an_object_is_exactly_what_the_wire_would_deliver(obj: Any) -> None:
    assume(obj is not None)
    if carriable(obj) is None:
        return  # travels the long way, as before: the receiver decodes (or refuses) it
    wanted = the_long_way(obj)
    assert not isinstance(wanted, Exception), f"carried, but the wire refuses it: {wanted}"
    assert_same(obj, wanted)


def test_the_messages_of_a_primitive_and_its_function_cross_as_objects() -> None:
    """Each message of the per-primitive path as the nodes build it is carried, not converted."""
    hot = [
        SmRequest("engine-1", operation="op2", function="insert_rivet", params=("drill_1", "0.5"), partners=("left_arm",), cell="c"),
        BridgeCommand("c-1", "left_arm", "execute", MoveJoints((0.1, 0.2))),
        BridgeFeedback("c-1", "left_arm", "done", result=MotionResult(("a", "b"), (0.1, 0.2), Pose(0.3, 0.0, 0.1)), t=4.25),
        SmStatus("left_arm", "primitive_end", "Motion", 2.0, operation="op2", function="f", primitive="set_speed(1)", index=0,
                 outcome="done", result={"kind": "motion", "joint_names": ["a"], "positions": [0.1], "tcp": None}),
        SmResult("engine-1", "left_arm", "succeeded", "op2", "insert_rivet", t_start=1.25, t_end=8.0, primitives=4),
        SyncMessage("left_arm", "op2:fbm", "arrived", "FullBodyMotion", 3.0),
        EngineEvent("operator", 1.5, "running", command="pause", source="/execution_engine/pause", accepted=False, answer="no"),
        EngineStatus("app", "running", 3, 10, 3.0, "op3", {"left_arm": GroupProgress("Motion", "op3", "f")}),
        SmStructure("left_arm", "Ready", ("Ready", "Motion"), (TransitionSpec("Ready", "motion_request", "Motion"),)),
    ]
    for obj in hot:
        assert carriable(obj) is not None, obj
        assert_same(obj, the_long_way(obj))
    assert carriable(SmStatus("left_arm", "transition", "Motion", float("nan"))) is None
    assert carriable(BridgeFeedback("c", "g", "done", result=MotionResult(("a",), (np.float64(0.5),)))) is None


# ------------------------------------------------------------------------ on the local bus
def test_a_carried_message_keeps_asynchronous_delivery_keep_last_and_transient_local(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[list[Any], list[Any], list[Any], list[Any]]:
        bus = LocalTransport(clock)
        sender, receiver = bus.create_node("sender"), bus.create_node("receiver")
        pub = TypedPublisher(sender, SmResult, "/g/sm/result", QoS(depth=2))
        got: list[Any] = []
        subscribe(receiver, SmResult, "/g/sm/result", got.append, lambda e: got.append(e), QoS(depth=2))
        for i in range(5):
            pub.publish(SmResult(f"r{i}", "g", "succeeded", t_end=float(i)))
        during = list(got)  # nothing inside publish
        await clock.sleep(0)
        latched = TypedPublisher(sender, SmStructure, "/g/sm/structure", LATCHED)
        latched.publish(SmStructure("g", "Ready", ("Ready",), ()))
        late_objects: list[Any] = []
        late_messages: list[Any] = []
        subscribe(receiver, SmStructure, "/g/sm/structure", late_objects.append, late_objects.append, LATCHED)
        receiver.create_subscription(typed.MachineStructureMsg, "/g/sm/structure", late_messages.append, LATCHED)
        await clock.sleep(0)
        return during, got, late_objects, late_messages

    during, got, late_objects, late_messages = run_sim(main)
    assert during == [] and [r.id for r in got] == ["r3", "r4"] and all(type(r) is SmResult for r in got)
    assert late_objects == [SmStructure("g", "Ready", ("Ready",), ())]
    assert [type(m) for m in late_messages] == [typed.MachineStructureMsg] and late_messages[0].states == ("Ready",)


def test_each_receiver_has_its_own_dicts_and_the_senders_later_changes_reach_nobody(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[SmStatus, SmStatus, list[Any]]:
        bus = LocalTransport(clock)
        sender, a, b = bus.create_node("sender"), bus.create_node("a"), bus.create_node("b")
        pub = TypedPublisher(sender, SmStatus, "/g/sm/status")
        got_a: list[SmStatus] = []
        got_b: list[SmStatus] = []
        raw: list[Any] = []
        subscribe(a, SmStatus, "/g/sm/status", got_a.append, pytest.fail)
        subscribe(b, SmStatus, "/g/sm/status", got_b.append, pytest.fail)
        b.create_subscription(typed.MachineStatusMsg, "/g/sm/status", raw.append)
        result = {"kind": "motion", "positions": [0.1, 0.2]}
        pub.publish(SmStatus("g", "primitive_end", "Motion", 1.0, result=result))
        result["positions"].append(9.0)  # the sender changes its dict after publishing
        await clock.sleep(0)
        assert got_a[0].result is not None
        got_a[0].result["positions"][0] = -1.0  # a receiver changes what it got
        return got_a[0], got_b[0], raw

    first, second, raw = run_sim(main)
    assert first.result == {"kind": "motion", "positions": [-1.0, 0.2]}
    assert second.result == {"kind": "motion", "positions": [0.1, 0.2]}
    assert typed.from_msg(SmStatus, raw[0], CLOCK).result == {"kind": "motion", "positions": [0.1, 0.2]}


def test_an_object_the_wire_would_change_travels_as_a_message_and_arrives_as_before(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[Any]:
        bus = LocalTransport(clock)
        sender, receiver = bus.create_node("sender"), bus.create_node("receiver")
        pub = TypedPublisher(sender, BridgeFeedback, "/g/bridge/feedback")
        got: list[Any] = []
        subscribe(receiver, BridgeFeedback, "/g/bridge/feedback", got.append, got.append)
        pub.publish(BridgeFeedback("c-1", "g", "done", error="", result=MotionResult(("a",), [1])))  # type: ignore[arg-type]
        pub.publish(BridgeFeedback("c-2", "g", "done", result={"kind": "teleport"}))  # type: ignore[arg-type]
        await clock.sleep(0)
        return got

    decoded, refused = run_sim(main)
    assert decoded.error is None and decoded.result == MotionResult(("a",), (1.0,)) and type(decoded.result.positions[0]) is float
    assert isinstance(refused, codec.WireError) and "/g/bridge/feedback" in str(refused) and "result_json" in str(refused)


def test_a_wrong_class_is_refused_at_publish(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        pub = TypedPublisher(LocalTransport(clock).create_node("n"), SmResult, "/g/sm/result", COMMANDS)
        with pytest.raises(Exception, match="carries SmResult, got SmRequest"):
            pub.publish(SmRequest("x", function="f"))  # type: ignore[arg-type]

    run_sim(main)


def test_a_primitive_crosses_engine_machine_and_bridge_without_one_conversion(run_sim: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """The point of it all: in one process no typed message is built or read on a function's path,
    engine -> machine -> bridge -> machine -> engine, and the engine gets the same result."""
    async def main(clock: Clock) -> tuple[SmResult, dict[str, int], list[Executed]]:
        bus = LocalTransport(clock)
        backend = ScriptedBackend(clock, NEXTAGE_OPEN)
        bridge = BridgeNode(bus.create_node("bridge"), backend)
        await bridge.start()
        params = {"group": "left_arm", "trajectory_db": ":memory:"}
        machine = GroupMachine(bus.create_node("left_arm_machine", parameters=params), APPLICATION_FUNCTIONS)
        task = asyncio.get_running_loop().create_task(machine.run())
        link = GroupLink(bus.create_node("engine"), "left_arm", 5.0)
        counts = {"to_msg": 0, "from_msg": 0}
        for name in counts:
            real = getattr(typed, name)
            monkeypatch.setattr(typed, name, lambda *a, _n=name, _f=real, **k: counts.__setitem__(_n, counts[_n] + 1) or _f(*a, **k))
        try:
            assert await link.link(5.0)
            result = await link.send(SmRequest(link.new_id(), operation="1", function="set_speed", params=("0.5",)))
            return result, counts, backend.executed("left_arm")
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            await bridge.close()

    result, counts, executed = run_sim(main)
    assert result.outcome == "succeeded" and result.primitives == 1 and type(result) is SmResult
    assert [e.primitive for e in executed] == [SetSpeed(0.5)]
    assert counts == {"to_msg": 0, "from_msg": 0}
