"""The machine's event queue: ordered, bounded waits, hand-back to the front, cancellation honoured."""
from __future__ import annotations

import asyncio
from typing import Any

import pytest

from node_transport.clock import Clock
from execution_engine.machine.events import EventQueue, FaultEvent, OperatorSignal


def test_events_come_in_order_and_put_back_goes_first(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[Any]:
        queue = EventQueue(clock)
        for command in ("pause", "resume", "stop"):
            queue.put(OperatorSignal(command, "test"))  # type: ignore[arg-type]
        first = await queue.get()
        queue.put_back(first)  # a state that could not use it hands it back
        return [await queue.get() for _ in range(3)]

    assert [e.command for e in run_sim(main)] == ["pause", "resume", "stop"]


def test_a_bounded_wait_times_out_in_run_time_and_a_put_wakes_it(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[Any, float, Any, float]:
        queue = EventQueue(clock)
        nothing = await queue.get(2.5)
        waited = clock.now()
        clock.call_later(1.0, queue.put, FaultEvent("x", "boom"))
        event = await queue.get(10.0)
        return nothing, waited, event, clock.now()

    nothing, waited, event, woke = run_sim(main)
    assert nothing is None and waited == pytest.approx(2.5)
    assert event == FaultEvent("x", "boom") and woke == pytest.approx(3.5)


def test_cancelling_the_waiting_state_is_not_taken_for_a_timeout(run_sim: Any) -> None:
    async def main(clock: Clock) -> tuple[bool, Any]:
        queue = EventQueue(clock)
        task = asyncio.ensure_future(queue.get(100.0))
        await clock.sleep(1.0)
        task.cancel()
        cancelled = False
        try:
            await task
        except asyncio.CancelledError:
            cancelled = True
        queue.put(FaultEvent("after", "cancel"))
        return cancelled, await queue.get(1.0)  # the queue is usable again

    cancelled, event = run_sim(main)
    assert cancelled and event == FaultEvent("after", "cancel")


def test_one_waiter_at_a_time_and_a_bounded_size(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        queue = EventQueue(clock, maxsize=2)
        waiting = asyncio.ensure_future(queue.get())
        await clock.sleep(0)
        with pytest.raises(RuntimeError, match="two states wait"):
            await queue.get()
        queue.put(FaultEvent("a", "1"))
        assert await waiting == FaultEvent("a", "1")
        queue.put(FaultEvent("b", "2"))
        queue.put(FaultEvent("c", "3"))
        with pytest.raises(RuntimeError, match="event queue full"):
            queue.put(FaultEvent("d", "4"))

    run_sim(main)
