"""The DDS transport's one receiving thread: if it stops by itself, the process must learn it.

Everything a DDS node hears comes through the waiter's thread; a waiter that died with only a
log line would leave a node that looks alive and hears nothing (a machine waiting for feedback
forever).  The transport ends as an rclpy one does when its executor dies: ``spin_error`` set,
``wait_closed`` returns, and the node process exits non-zero (``ros_main``).
"""
from __future__ import annotations

import asyncio
from typing import Any

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport

BOUND = 10.0


class BrokenWaitSet:
    """A waitset whose wait fails, as a defect in the binding or a deleted entity would make it."""

    def wait(self, timeout: Any) -> None:
        raise RuntimeError("waitset broken")

    def attach(self, condition: Any) -> None:
        pass

    def detach(self, condition: Any) -> None:
        pass


def test_a_waiter_that_stops_by_itself_closes_the_transport_with_its_error(dds_env: dict[str, str]) -> None:
    env = dds_env

    async def main(clock: Clock) -> tuple[BaseException | None, BaseException | None, bool]:
        transport = DdsTransport(clock, env=env)
        try:
            healthy = transport.spin_error
            transport.waiter._waitset = BrokenWaitSet()  # noqa: SLF001 - the thread takes it at its next wait
            await asyncio.wait_for(transport.wait_closed(), BOUND)
            thread = transport.waiter._thread  # noqa: SLF001
            # it reports before it returns: the transport may learn of the stop a moment before the thread has ended
            await asyncio.to_thread(thread.join, BOUND)
            return healthy, transport.spin_error, thread.is_alive()
        finally:
            await transport.shutdown()

    healthy, error, alive = run_with_clock(main, real_clock())
    assert healthy is None
    assert isinstance(error, RuntimeError) and str(error) == "waitset broken"
    assert not alive
