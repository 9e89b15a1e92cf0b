"""The fake rclpy's context: ``rclpy.init``, ``ok``, ``shutdown`` and ``remove_ros_args``, as rcl does them.

``init`` parses ``--ros-args`` with rcl's rules (``ros_fake_args``) and refuses what rcl refuses, with rcl's
exception types; nodes read their renames, parameters and log level from here.  ``shutdown`` wakes every executor
(they leave ``spin`` with :class:`ExternalShutdownException`, as rclpy's do).  One context serves the process; the
fake rclpy's ``install`` resets it between tests.
"""
from __future__ import annotations

import enum
import sys
from collections.abc import Callable
from typing import Any

from ros_fake_args import RosArguments


class ExternalShutdownException(Exception):
    """Raised out of ``spin`` when the context is shut down while spinning (as rclpy does)."""


class SignalHandlerOptions(enum.Enum):
    NO = 0
    SIGINT = 1
    SIGTERM = 2
    ALL = 3


class Context:
    """rclpy's default context, with counts of its inits and shutdowns for the tests to read."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Back to before any ``init``, with no shutdown callbacks: a fresh process."""
        self.initialised = False
        self.args: list[str] = []
        self.ros_args = RosArguments([])
        self.init_kwargs: dict[str, Any] = {}
        self.on_shutdown_callbacks: list[Callable[[], None]] = []
        self.init_count = 0
        self.shutdown_count = 0

    def ok(self) -> bool:
        return self.initialised

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        self.on_shutdown_callbacks.append(callback)


CONTEXT = Context()


def init(*, args: list[str] | None = None, context: Any = None, domain_id: int | None = None, signal_handler_options: Any = None) -> None:
    if CONTEXT.initialised:
        raise RuntimeError("rcl_init called while already initialized")
    argv = list(args if args is not None else sys.argv)
    ros_args = RosArguments(argv)  # raises RCLError / UnknownROSArgsError as rcl_init does
    CONTEXT.initialised = True
    CONTEXT.args = argv
    CONTEXT.ros_args = ros_args
    CONTEXT.init_kwargs = {"args": args, "signal_handler_options": signal_handler_options}
    CONTEXT.init_count += 1


def ok(context: Any = None) -> bool:
    return CONTEXT.ok()


def shutdown(context: Any = None) -> None:
    if not CONTEXT.initialised:
        raise RuntimeError("rcl_shutdown already called on the given context")
    CONTEXT.initialised = False
    CONTEXT.shutdown_count += 1
    for callback in list(CONTEXT.on_shutdown_callbacks):
        callback()


def remove_ros_args(args: list[str] | None = None) -> list[str]:
    out: list[str] = []
    in_ros = False
    for arg in args if args is not None else sys.argv:
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--" and in_ros:
            in_ros = False
        elif not in_ros:
            out.append(arg)
    return out
