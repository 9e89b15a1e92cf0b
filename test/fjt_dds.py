"""A fake ros2_control driver (fake_fjt_server.FakeDriver) serving over Cyclone DDS from a thread of the test: the
peer the ``ros2-control`` back end reaches over the wire in the command-line tests."""
from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterator

from fake_fjt_server import FakeDriver

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.port import Node

#: Builds the driver on its node and clock.
Build = Callable[[Node, Clock], FakeDriver]


@contextlib.contextmanager
def driver_on_dds(env: dict[str, str], build: Build, bound: float) -> Iterator[FakeDriver]:
    """The driver serving in ``env``'s domain while the ``with`` block runs (at most ``bound`` + 10 s), then closed."""
    done, started, out = threading.Event(), threading.Event(), {}

    def serve() -> None:
        async def main(clock: Clock) -> None:
            transport = DdsTransport(clock, [], env=env)
            driver = out["driver"] = build(transport.create_node("controller_manager"), clock)
            started.set()
            try:
                deadline = clock.now() + bound + 10.0
                while not done.is_set() and clock.now() < deadline:
                    await clock.sleep(0.05)
            finally:
                await driver.close()
                await transport.shutdown()

        run_with_clock(main, real_clock())

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    try:
        assert started.wait(30.0), "the stand-in controller did not start"
        yield out["driver"]
    finally:
        done.set()
        server.join(30.0)


def base_env() -> dict[str, str]:
    """This process's environment without its ROS and Cyclone settings (a test's domain replaces them)."""
    return {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "CYCLONEDDS", "RMW_"))}
