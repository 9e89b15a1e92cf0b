"""Python ``logging`` records of a ROS process, handed to the node's rclpy logger.

Every module of the project logs through Python's ``logging``; a ROS user reads logs in the
console of ``ros2 launch``, in rqt_console and on ``/rosout``, and sets their verbosity with
``--ros-args --log-level``.  Those are rcutils' and only reach a record given to an rclpy
logger of a node.  So a ROS process attaches one :class:`RosLogHandler` to the root logger:
each record goes to the rclpy logger of the node it belongs to (by logger name), or of the
process's first node, and rcutils prints it, publishes it on ``/rosout`` and filters it by the
``--log-level`` the user gave -- which also sets the Python level, so nothing rcutils would
print is dropped before it gets there.

A warning that repeats is aggregated before it is forwarded, as every console of ours does
(:class:`~node_transport.console_log.AggregatingHandler`): the first of a kind at once, then one
line per kind and second with its count, so neither the console of ``ros2 launch`` nor
``/rosout`` gets the flood.  What is held when the process's last node goes is forwarded then.
"""
from __future__ import annotations

import logging
import threading
from typing import Any

from node_transport.console_log import AggregatingHandler

#: rcutils severities (rclpy.logging.LoggingSeverity values) -- the same numbers as Python's levels.
_SEVERITIES = (10, 20, 30, 40, 50)


def ros_severity(levelno: int) -> int:
    """The rcutils severity of a Python level: the highest one not above it (DEBUG at least)."""
    chosen = _SEVERITIES[0]
    for severity in _SEVERITIES:
        if levelno >= severity:
            chosen = severity
    return chosen


class RosLogHandler(logging.Handler):
    """Forwards records to rclpy node loggers; never raises into the code that logged."""

    def __init__(self) -> None:
        super().__init__(logging.NOTSET)
        self._lock_nodes = threading.Lock()
        self._loggers: dict[str, Any] = {}  # python logger name -> rclpy logger
        self._default: Any = None

    def attach(self, python_name: str, ros_logger: Any) -> None:
        """Route records of ``python_name`` (and its children) to ``ros_logger``; the first attached
        node also takes every record no node claims."""
        with self._lock_nodes:
            self._loggers[python_name] = ros_logger
            if self._default is None:
                self._default = ros_logger

    def detach(self, python_name: str) -> None:
        with self._lock_nodes:
            logger = self._loggers.pop(python_name, None)
            if logger is self._default:
                self._default = next(iter(self._loggers.values()), None)

    @property
    def empty(self) -> bool:
        return not self._loggers

    def routes(self) -> list[str]:
        """The Python logger names routed to a node."""
        with self._lock_nodes:
            return list(self._loggers)

    def _target(self, name: str) -> Any:
        with self._lock_nodes:
            probe = name
            while probe:
                logger = self._loggers.get(probe)
                if logger is not None:
                    return logger
                probe = probe.rpartition(".")[0]
            return self._default

    def emit(self, record: logging.LogRecord) -> None:
        target = self._target(record.name)
        if target is None:
            return
        try:
            text = record.getMessage()
            if record.exc_info:
                text = f"{text}\n{logging.Formatter().formatException(record.exc_info)}"
            if record.name not in self._loggers:  # a module's logger: say which, the node is rcutils' name
                text = f"[{record.name}] {text}"
            _log(target, ros_severity(record.levelno), text)
        except Exception:  # noqa: BLE001 - logging must never break the caller
            self.handleError(record)


def _log(target: Any, severity: int, text: str) -> None:
    """One call site per severity: rclpy ties each call site (file, line) to the severity of its
    first call and raises ValueError when the same site logs at another one."""
    if severity >= 50:
        target.fatal(text)
    elif severity >= 40:
        target.error(text)
    elif severity >= 30:
        target.warning(text)
    elif severity >= 20:
        target.info(text)
    else:
        target.debug(text)


_HANDLER_LOCK = threading.Lock()
_HANDLER: RosLogHandler | None = None
_FRONT: AggregatingHandler | None = None  # on the root logger: aggregates, then hands to _HANDLER


def install(python_name: str, ros_logger: Any) -> RosLogHandler:
    """Attach the process's handler to the root logger (once, behind the aggregation) and route
    ``python_name`` to ``ros_logger``; the root level follows the rclpy logger's effective level
    (``--log-level``)."""
    global _HANDLER, _FRONT
    with _HANDLER_LOCK:
        if _HANDLER is None:
            _HANDLER = RosLogHandler()
            _FRONT = AggregatingHandler(_HANDLER)
            logging.getLogger().addHandler(_FRONT)
        handler = _HANDLER
    handler.attach(python_name, ros_logger)
    try:
        level = int(ros_logger.get_effective_level())
    except Exception:  # noqa: BLE001 - an rclpy without levels: keep Python's
        level = 0
    if level > 0:
        logging.getLogger().setLevel(level)
    return handler


def uninstall(python_name: str) -> None:
    """Stop routing ``python_name``; the handler leaves the root logger with its last node, after
    forwarding what the aggregation still holds (while that node can still log it)."""
    global _HANDLER, _FRONT
    with _HANDLER_LOCK:
        handler, front = _HANDLER, _FRONT
        if handler is None:
            return
        if front is not None and handler.routes() in ([python_name], []):  # the last node goes
            logging.getLogger().removeHandler(front)
            front.close()  # what it holds is forwarded now, while the node can still log it
            _FRONT = None
        handler.detach(python_name)
        if handler.empty:
            _HANDLER = None
