"""The SMACH-style core: outcomes, build-time checks, userdata windows, history, preemption, introspection."""
from __future__ import annotations

import asyncio
from collections.abc import MutableMapping
from typing import Any

import pytest

from node_transport.clock import Clock
from execution_engine.smach import (
    HISTORY,
    CallbackState,
    ConsistencyError,
    State,
    StateMachine,
    StructureInfo,
    TransitionRecord,
    UserData,
)


class Recorder:
    def __init__(self) -> None:
        self.structures: list[StructureInfo] = []
        self.entered: list[tuple[str, float]] = []
        self.transitions: list[TransitionRecord] = []

    def on_structure(self, structure: StructureInfo) -> None:
        self.structures.append(structure)

    def on_enter(self, machine: str, state: str, t: float) -> None:
        self.entered.append((state, t))

    def on_transition(self, record: TransitionRecord) -> None:
        self.transitions.append(record)


def returning(outcome: str, *, delay: float = 0.0, clock: Clock | None = None, **kw: Any) -> CallbackState:
    async def run(ud: MutableMapping[str, Any]) -> str:
        if delay and clock:
            await clock.sleep(delay)
        return outcome

    return CallbackState([outcome], run, **kw)


def test_runs_states_in_outcome_order_and_records_timed_transitions(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[str, Recorder]:
        sm = StateMachine("demo", ("done",), clock)
        sm.add("A", returning("next", delay=1.5, clock=clock), {"next": "B"})
        sm.add("B", returning("finish", delay=0.5, clock=clock), {"finish": "done"})
        rec = Recorder()
        sm.add_observer(rec)
        return await sm.execute(UserData()), rec

    outcome, rec = run_sim(main)
    assert outcome == "done"
    assert [(r.source, r.outcome, r.target) for r in rec.transitions] == [("A", "next", "B"), ("B", "finish", "done")]
    assert [r.t for r in rec.transitions] == [pytest.approx(1.5), pytest.approx(2.0)]
    assert rec.entered == [("A", pytest.approx(0.0)), ("B", pytest.approx(1.5))]
    assert rec.structures[0].states == ("A", "B") and rec.structures[0].initial == "A"
    assert ("A", "next", "B") in rec.structures[0].transitions


def test_check_reports_every_wiring_defect_at_once(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        sm = StateMachine("broken", ("done",), clock)
        sm.add("A", CallbackState(["ok", "fail"], lambda ud: None), {"ok": "B"})  # type: ignore[arg-type,return-value]
        sm.add("B", returning("x"), {"x": "Nowhere", "y": "A"})
        sm.add("C", returning("ok"), {"ok": "done"})
        with pytest.raises(ConsistencyError) as err:
            await sm.execute()
        problems = "\n".join(err.value.problems)
        assert "outcome 'fail' of state 'A' is not mapped" in problems
        assert "'Nowhere': no such state or outcome (dangling)" in problems
        assert "maps 'y', which it does not declare" in problems
        assert "state 'C' can never be entered" in problems

    run_sim(main)


def test_state_returning_an_undeclared_outcome_is_an_error(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        async def liar(ud: MutableMapping[str, Any]) -> str:
            return "surprise"

        sm = StateMachine("m", ("done",), clock)
        sm.add("A", CallbackState(["ok"], liar), {"ok": "done"})
        with pytest.raises(RuntimeError, match="returned 'surprise'"):
            await sm.execute()
        assert sm.active_state is None

    run_sim(main)


def test_userdata_window_allows_declared_keys_only(run_sim: Any) -> None:
    async def main(clock: Clock) -> UserData:
        async def producer(ud: MutableMapping[str, Any]) -> str:
            ud["part"] = "rivet_1"
            return "ok"

        async def consumer(ud: MutableMapping[str, Any]) -> str:
            ud["seen"] = ud["part"]
            return "ok"

        async def snooper(ud: MutableMapping[str, Any]) -> str:
            return "ok" if ud["secret"] else "ok"

        sm = StateMachine("m", ("done",), clock)
        sm.add("P", CallbackState(["ok"], producer, output_keys=["part"]), {"ok": "C"})
        sm.add("C", CallbackState(["ok"], consumer, input_keys=["part"], output_keys=["seen"]), {"ok": "done"})
        data = UserData(secret=1)
        await sm.execute(data)

        sm2 = StateMachine("m2", ("done",), clock)
        sm2.add("S", CallbackState(["ok"], snooper), {"ok": "done"})
        with pytest.raises(KeyError, match="state 'S' reads userdata key 'secret'"):
            await sm2.execute(UserData(secret=1))
        return data

    data = run_sim(main)
    assert data["seen"] == "rivet_1"


def test_history_returns_to_the_state_that_was_interrupted(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[str]:
        visits: list[str] = []

        def work(name: str) -> CallbackState:
            async def run(ud: MutableMapping[str, Any]) -> str:
                visits.append(name)
                count = ud["count"] = ud["count"] + 1
                return "pause" if count in (1, 3) else "ok"

            return CallbackState(["pause", "ok"], run, input_keys=["count"], output_keys=["count"])

        async def pause(ud: MutableMapping[str, Any]) -> str:
            visits.append("Pause")
            return "resume"

        sm = StateMachine("m", ("done",), clock)
        sm.add("Ready", returning("go"), {"go": "Motion"})
        sm.add("Motion", work("Motion"), {"pause": "Pause", "ok": "Vision"})
        sm.add("Vision", work("Vision"), {"pause": "Pause", "ok": "done"})
        sm.add("Pause", CallbackState(["resume"], pause), {"resume": HISTORY})
        await sm.execute(UserData(count=0))
        return visits

    assert run_sim(main) == ["Motion", "Pause", "Motion", "Vision", "Pause", "Vision"]


def test_preemption_is_cooperative_and_serviced(run_sim: Any) -> None:
    class Waiting(State):
        def __init__(self, clock: Clock) -> None:
            super().__init__(["finished", "preempted"])
            self.clock = clock

        async def execute(self, userdata: MutableMapping[str, Any]) -> str:
            work = asyncio.ensure_future(self.clock.sleep(100.0))
            stop = asyncio.ensure_future(self.wait_preempt())
            done, pending = await asyncio.wait({work, stop}, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
            return "preempted" if stop in done else "finished"

    async def main(clock: Clock) -> tuple[str, float, bool]:
        state = Waiting(clock)
        sm = StateMachine("m", ("done", "aborted"), clock)
        sm.add("W", state, {"finished": "done", "preempted": "aborted"})
        clock.call_later(2.0, sm.request_preempt)
        outcome = await sm.execute()
        return outcome, clock.now(), state.preempt_requested

    outcome, t, still_flagged = run_sim(main)
    assert outcome == "aborted"
    assert t == pytest.approx(2.0)
    assert not still_flagged  # serviced, so the next run starts clean


def test_nested_machines_and_transition_bound(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        inner = StateMachine("inner", ("inner_done",), clock)
        inner.add("I", returning("ok"), {"ok": "inner_done"})
        outer = StateMachine("outer", ("done",), clock)
        outer.add("Sub", inner, {"inner_done": "done"})
        assert await outer.execute() == "done"

        loop = StateMachine("loop", ("done",), clock, max_transitions=10)
        loop.add("A", returning("again"), {"again": "B"})
        loop.add("B", returning("again"), {"again": "A"})
        with pytest.raises(RuntimeError, match="exceeded 10 transitions"):
            await loop.execute()

    run_sim(main)


def test_labels_must_be_unique_and_not_outcomes(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        sm = StateMachine("m", ("done",), clock)
        sm.add("A", returning("ok"), {"ok": "done"})
        with pytest.raises(ValueError, match="already has a state 'A'"):
            sm.add("A", returning("ok"), {"ok": "done"})
        with pytest.raises(ValueError, match="clashes with an outcome"):
            sm.add("done", returning("ok"), {"ok": "done"})
        with pytest.raises(ValueError, match="declares no outcomes"):
            CallbackState([], returning("x").execute)

    run_sim(main)
