"""A function the engine sent to a group and has no result of yet, and the end of a run that cannot go on.

Shared by the engine's two ways of running an application, operation by operation (engine/engine.py)
and each group on its own (``sync="flags"``, engine/flags_mode.py), and by a resumed run's first
operation (checkpoint/resume.py), which all end a run by raising :class:`ApplicationAborted`.
"""
from __future__ import annotations

import asyncio
from dataclasses import dataclass

from execution_engine.app_model.model import Call
from node_transport.wire import SmRequest, SmResult


@dataclass
class Dispatch:
    """A function sent to a group and not yet answered."""

    call: Call
    request: SmRequest
    future: asyncio.Future[SmResult]
    deadline: float


class ApplicationAborted(Exception):
    """The run cannot go on (policy exhausted, operator stop); the report says why."""
