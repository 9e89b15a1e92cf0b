"""A state: declared outcomes, ``execute(userdata) -> outcome``, cooperative preemption.

Outcomes are declared up front so a container can check, before anything runs, that each one
leads somewhere.  ``execute`` is a coroutine: a state that waits (for a robot, an operator)
must not block the machines of the other groups.  Preemption is cooperative, as in SMACH:
``request_preempt`` raises a flag that a long-running state checks (or awaits) and answers by
returning one of its outcomes; the container then calls ``service_preempt``.
"""
from __future__ import annotations

import asyncio
from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from typing import Any


class State(ABC):
    """One state of a machine."""

    def __init__(
        self,
        outcomes: Iterable[str],
        *,
        input_keys: Iterable[str] = (),
        output_keys: Iterable[str] = (),
    ) -> None:
        self.outcomes: tuple[str, ...] = tuple(dict.fromkeys(outcomes))
        if not self.outcomes:
            raise ValueError(f"{type(self).__name__} declares no outcomes")
        self.input_keys: frozenset[str] = frozenset(input_keys)
        self.output_keys: frozenset[str] = frozenset(output_keys)
        self._preempt = asyncio.Event()

    @abstractmethod
    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        """Do the state's work and return one of :attr:`outcomes`."""

    # --------------------------------------------------------------------------- preemption
    def request_preempt(self) -> None:
        """Ask the state to finish early; it decides when and with which outcome."""
        self._preempt.set()

    @property
    def preempt_requested(self) -> bool:
        return self._preempt.is_set()

    def service_preempt(self) -> None:
        """Acknowledge a preemption so the next execution starts clean."""
        self._preempt.clear()

    async def wait_preempt(self) -> None:
        """Await a preemption request (to race against the state's own work)."""
        await self._preempt.wait()


class CallbackState(State):
    """A state whose work is a coroutine function: handy for small machines and tests."""

    def __init__(
        self,
        outcomes: Iterable[str],
        callback: Callable[[MutableMapping[str, Any]], Awaitable[str]],
        *,
        input_keys: Iterable[str] = (),
        output_keys: Iterable[str] = (),
    ) -> None:
        super().__init__(outcomes, input_keys=input_keys, output_keys=output_keys)
        self._callback = callback

    async def execute(self, userdata: MutableMapping[str, Any]) -> str:
        return await self._callback(userdata)
