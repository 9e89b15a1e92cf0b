"""A node's logger in the fake rclpy, and ``/rosout`` as the list of what it let through.

rclpy's logger has rules that bit the ros transport on a real Jazzy: severities are ints, ``--log-level`` filters
them, and one call site may not log at two severities (ValueError).  The fake keeps those rules and records each
message that passes on :data:`ROSOUT` for the tests to read.
"""
from __future__ import annotations

import sys
from typing import Any

ROSOUT: list[tuple[str, int, str]] = []  # (logger name, severity, message) of every log that passed its level


class FakeLogger:
    """rclpy's RcutilsLogger: severities as ints, a level from ``--log-level``, records on /rosout.

    As in rclpy, each call site (the first frame outside rclpy: file, function, line, bytecode
    offset) keeps the severity of its first call; logging at another severity from the same
    site raises ValueError."""

    def __init__(self, name: str, level: int) -> None:
        self.name = name
        self.level = level
        self.contexts: dict[tuple[str, str, int, int], int] = {}

    def get_effective_level(self) -> int:
        return self.level

    def is_enabled_for(self, severity: int) -> bool:
        return severity >= self.level

    def log(self, message: str, severity: int, **kwargs: Any) -> bool:
        if severity not in (10, 20, 30, 40, 50):
            raise ValueError(f"{severity} is not a valid LoggingSeverity")
        if not isinstance(message, str):
            raise TypeError("message must be a string")
        if not self.is_enabled_for(severity):
            return False
        frame = sys._getframe(1)
        while frame.f_code.co_filename == __file__:  # rclpy's _find_caller: skip the logger itself
            frame = frame.f_back  # type: ignore[assignment]
        caller = (frame.f_code.co_filename, frame.f_code.co_name, frame.f_lineno, frame.f_lasti)
        if self.contexts.setdefault(caller, severity) != severity:
            raise ValueError("Logger severity cannot be changed between calls.")
        ROSOUT.append((self.name, severity, message))
        return True

    def debug(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 10, **kwargs)

    def info(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 20, **kwargs)

    def warning(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 30, **kwargs)

    def error(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 40, **kwargs)

    def fatal(self, message: str, **kwargs: Any) -> bool:
        return self.log(message, 50, **kwargs)
