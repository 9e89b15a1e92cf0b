"""Start-up and shutdown of one ROS 2 node process, shared by every ``ros2 run`` entry point.

Each executable of the package (engine, group machine, each bridge) is one node in one
process.  What they share lives here once: the real clock and its loop, the rclpy transport,
the node, signal handling (SIGINT/SIGTERM stop the loop, which then shuts rclpy down in order),
stopping when rclpy goes away by itself, and an exit code a launch file or a shell can rely on.

An entry point only supplies a *body*: ``async def body(node, outcome)`` declares its
parameters, builds its object and serves until cancelled.  It reports bad configuration by
raising :class:`StartupError` (or by letting a ``TransportError`` / ``ValueError`` out of
:func:`startup_errors`), and sets ``outcome.code`` for the exit code it wants when stopped.

Only the clock and the transport port are imported here, so bridge entry points in
``robot_bridges`` can use it without pulling in the engine.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import sys
from collections.abc import Awaitable, Callable, Iterator, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.port import Node, RosArgumentsError, TransportError
from node_transport.ros import RosTransport  # rclpy itself is imported only when one starts
from node_transport.selection import dds_transport, split_transport

log = logging.getLogger(__name__)


class ExitCode(IntEnum):
    """What a node process exits with."""

    OK = 0  # stopped by a signal or by ROS, or finished, with nothing wrong
    FAILED = 1  # the work failed: invalid application, failed run, robot unreachable
    USAGE = 2  # bad parameters or arguments: fix the launch file / command line
    INTERNAL = 3  # a defect or a middleware failure; the log has the traceback


class StartupError(Exception):
    """A node cannot start; the message is printed as is, the code becomes the exit code."""

    def __init__(self, message: str, code: ExitCode = ExitCode.USAGE) -> None:
        super().__init__(message)
        self.code = code


@dataclass
class Outcome:
    """The exit code the process will use if it is stopped now; a body updates it as it goes."""

    code: ExitCode = ExitCode.OK


NodeBody = Callable[[Node, Outcome], Awaitable[None]]
TransportFactory = Callable[[Clock, Sequence[str]], "RosTransport"]


@contextlib.contextmanager
def startup_errors() -> Iterator[None]:
    """Turn configuration errors raised while building a node's objects into a USAGE exit."""
    try:
        yield
    except TransportError as error:  # names the node and the parameter already
        raise StartupError(str(error)) from None
    except (ValueError, LookupError) as error:
        raise StartupError(f"{type(error).__name__}: {error}") from None


def warn_undeclared(node: Node) -> None:
    """Log parameters given to the node that no code declared: almost always a typo."""
    stray = node.undeclared_overrides()
    if stray:
        node.logger.warning(
            "%s: parameter(s) %s given but not declared by this node (a typo?); declared: %s",
            node.fully_qualified_name,
            ", ".join(stray),
            ", ".join(sorted(node.declared_parameters())),
        )


async def serve_forever() -> None:
    """Keep a node's services and subscriptions alive until the process is stopped."""
    await asyncio.get_running_loop().create_future()


def run_node(
    default_name: str,
    body: NodeBody,
    argv: Sequence[str] | None = None,
    *,
    clock: Clock | None = None,
    transport_factory: TransportFactory | None = None,
) -> int:
    """Run one node process to its end and return its exit code (see :class:`ExitCode`).

    ``default_name`` is the node's name unless the command line renames it (``-r __node:=...``).
    """
    # No Python log handler here: on ROS every record goes to the node's rclpy logger, which
    # prints it, publishes it on /rosout and honours --log-level (transport/ros_logging.py).
    try:  # --transport dds: the same node over Cyclone DDS, without a ROS install
        chosen, args = split_transport(sys.argv if argv is None else argv)
    except RosArgumentsError as error:
        print(f"{default_name}: {error}", file=sys.stderr)
        return int(ExitCode.USAGE)
    factory = transport_factory or (dds_transport if chosen == "dds" else _ros_transport)

    async def main(run_clock: Clock) -> int:
        return await serve_node(run_clock, default_name, body, args, factory)

    return int(run_with_clock(main, clock or real_clock()))


def _ros_transport(clock: Clock, argv: Sequence[str]) -> RosTransport:
    return RosTransport(clock, argv)


async def serve_node(
    clock: Clock, default_name: str, body: NodeBody, argv: Sequence[str], transport_factory: TransportFactory
) -> ExitCode:
    """The process's life on its loop: transport up, node up, body until stopped, all down.

    SIGINT/SIGTERM are handled from the first moment to the last: installed before rclpy starts
    and removed only once it is down, so a signal during start-up or shutdown is an orderly stop,
    never a KeyboardInterrupt through rclpy's teardown.
    """
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    installed = _install_signal_handlers(loop, stop.set)
    try:
        try:
            transport = transport_factory(clock, argv)
        except RosArgumentsError as error:
            print(f"{default_name}: bad ROS arguments: {error}", file=sys.stderr)
            return ExitCode.USAGE
        except TransportError as error:
            print(f"{default_name}: {error}", file=sys.stderr)
            return ExitCode.INTERNAL
        try:
            extra = transport.user_args(argv)
            if extra:
                print(
                    f"{default_name}: unexpected argument(s) {' '.join(extra)}; "
                    "give parameters as: --ros-args -p name:=value",
                    file=sys.stderr,
                )
                return ExitCode.USAGE
            try:
                node = transport.create_node(default_name)
            except TransportError as error:
                print(f"{default_name}: {error}", file=sys.stderr)
                return ExitCode.USAGE
            return await _run_body(node, body, transport, stop)
        finally:
            await transport.shutdown()
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)


async def _run_body(node: Node, body: NodeBody, transport: RosTransport, stop: asyncio.Event) -> ExitCode:
    loop = asyncio.get_running_loop()
    outcome = Outcome()
    work = loop.create_task(body(node, outcome), name=f"{node.fully_qualified_name} body")
    stopped = loop.create_task(stop.wait(), name="signal")
    closed = loop.create_task(transport.wait_closed(), name="rclpy closed")
    try:
        done, _ = await asyncio.wait({work, stopped, closed}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in (stopped, closed):
            task.cancel()
    if work not in done:
        node.logger.info("%s: stopping (%s)", node.fully_qualified_name, "signal" if stopped in done else "ROS shut down")
        work.cancel()
        for result in await asyncio.gather(work, return_exceptions=True):
            if isinstance(result, Exception):  # cleanup failed: the log must say so
                node.logger.error("%s: error while stopping: %s: %s", node.fully_qualified_name, type(result).__name__, result)
        if closed in done and transport.spin_error is not None:
            return ExitCode.INTERNAL
        return outcome.code
    try:
        work.result()
    except StartupError as error:
        text = str(error)
        prefix = f"{node.fully_qualified_name}: "
        print(text if text.startswith(prefix) else prefix + text, file=sys.stderr)
        return error.code
    except Exception:  # noqa: BLE001 - a defect: say so with the traceback, exit non-zero
        node.logger.exception("%s: stopped by an unexpected error", node.fully_qualified_name)
        return ExitCode.INTERNAL
    return outcome.code


def _install_signal_handlers(loop: asyncio.AbstractEventLoop, callback: Callable[[], Any]) -> list[int]:
    installed = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, callback)
        except (NotImplementedError, RuntimeError, ValueError):  # not the main thread, or no signals here
            continue
        installed.append(sig)
    return installed
