"""The ROS graph of the fake rclpy: every endpoint of every fake process, and DDS discovery between them.

Discovery takes time on a real middleware, and code that uses an endpoint before its peer has matched loses what
it sends; the ros transport must wait for the match (``wait_until_matched``), so the fake makes every pair of
endpoints match only ``match_delay`` wall seconds after both exist.  One graph serves all fake nodes; the fake
rclpy's ``install`` resets it between tests.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, Protocol


class Endpoint(Protocol):
    """Anything discovery matches: a publisher, subscription, service or client."""

    destroyed: bool


class Graph:
    """Everything the middleware would do between nodes of all fake processes, discovery included.

    The tables hold the fake endpoints (``ros_fake_topics``, ``ros_fake_services``) by topic or service name.
    """

    def __init__(self, match_delay: float = 0.02) -> None:
        self.reset(match_delay)

    def reset(self, match_delay: float = 0.02) -> None:
        """Forget every endpoint and match: a new graph, as a fresh middleware would be."""
        self.lock = threading.RLock()
        self.match_delay = match_delay  # wall seconds from both endpoints existing to their match
        self.subscriptions: dict[str, list[Any]] = {}
        self.publishers: dict[str, list[Any]] = {}
        self.services: dict[str, list[Any]] = {}
        self.clients: list[Any] = []
        self.matched: set[tuple[int, int]] = set()
        self.timers: list[threading.Timer] = []
        self.lost: list[tuple[str, Any]] = []  # (topic, message) published to a reader not matched yet

    def discover(self, writer: Endpoint, reader: Endpoint, on_match: Callable[[], None] | None = None) -> None:
        """Match ``writer`` and ``reader`` after the discovery delay (at once with a delay of 0)."""

        def match() -> None:
            with self.lock:
                if writer.destroyed or reader.destroyed:
                    return
                self.matched.add((id(writer), id(reader)))
            if on_match is not None:
                on_match()

        if self.match_delay <= 0:
            match()
            return
        timer = threading.Timer(self.match_delay, match)
        timer.daemon = True
        with self.lock:
            self.timers.append(timer)
        timer.start()

    def is_matched(self, writer: Endpoint, reader: Endpoint) -> bool:
        with self.lock:
            return (id(writer), id(reader)) in self.matched

    def close(self) -> None:
        with self.lock:
            for timer in self.timers:
                timer.cancel()
            self.timers.clear()


GRAPH = Graph()
