"""The state machine container: labelled states, outcome -> next-state maps, checked when built.

A machine that can reach an outcome nobody handles stops in a way no operator can explain.
So :meth:`StateMachine.check` (run by :meth:`execute` before the first state) refuses a machine
with an unmapped outcome, a target that is neither a state nor a container outcome, no initial
state, or a state that can never be entered -- all problems at once.

One extension over SMACH: a transition may target :data:`HISTORY`, meaning "the state that was
active before the current one".  Pause needs it: whichever working state was paused is the one
``resume`` must return to (a statechart history pseudo-state).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, MutableMapping
from dataclasses import dataclass
from typing import Any

from node_transport.clock import Clock
from execution_engine.smach.introspection import MachineObserver, StructureInfo, TransitionRecord
from execution_engine.smach.state import State
from execution_engine.smach.userdata import UserData

HISTORY = "<history>"


class ConsistencyError(ValueError):
    """The machine's wiring is wrong; ``problems`` lists every defect found."""

    def __init__(self, machine: str, problems: list[str]) -> None:
        self.problems = problems
        super().__init__(f"state machine {machine!r} is inconsistent:\n  " + "\n  ".join(problems))


@dataclass
class _Entry:
    state: State
    transitions: dict[str, str]


class StateMachine(State):
    """A container of states; itself a state, so machines nest."""

    def __init__(
        self,
        name: str,
        outcomes: tuple[str, ...],
        clock: Clock,
        *,
        input_keys: tuple[str, ...] = (),
        output_keys: tuple[str, ...] = (),
        max_transitions: int | None = None,
    ) -> None:
        super().__init__(outcomes, input_keys=input_keys, output_keys=output_keys)
        self.name = name
        self.clock = clock
        self.max_transitions = max_transitions
        self._states: dict[str, _Entry] = {}
        self._initial: str | None = None
        self._observers: list[MachineObserver] = []
        self._active: str | None = None
        self._previous: str | None = None
        self._checked = False

    # ---------------------------------------------------------------------------- building
    def add(self, label: str, state: State, transitions: Mapping[str, str]) -> None:
        """Add ``state`` under ``label``; ``transitions`` maps each of its outcomes to a target."""
        if label in self._states:
            raise ValueError(f"state machine {self.name!r} already has a state {label!r}")
        if label in self.outcomes or label == HISTORY:
            raise ValueError(f"state label {label!r} clashes with an outcome of {self.name!r}")
        self._states[label] = _Entry(state, dict(transitions))
        if self._initial is None:
            self._initial = label
        self._checked = False

    def set_initial(self, label: str) -> None:
        self._initial = label
        self._checked = False

    def check(self) -> None:
        """Raise :class:`ConsistencyError` listing every wiring defect."""
        problems: list[str] = []
        if self._initial is None:
            problems.append("no states")
        elif self._initial not in self._states:
            problems.append(f"initial state {self._initial!r} does not exist")
        for label, entry in self._states.items():
            for outcome in entry.state.outcomes:
                if outcome not in entry.transitions:
                    problems.append(f"outcome {outcome!r} of state {label!r} is not mapped")
            for outcome, target in entry.transitions.items():
                if outcome not in entry.state.outcomes:
                    problems.append(f"state {label!r} maps {outcome!r}, which it does not declare as an outcome")
                if target != HISTORY and target not in self._states and target not in self.outcomes:
                    problems.append(f"state {label!r} --{outcome}--> {target!r}: no such state or outcome (dangling)")
        reachable = self._reachable()
        for label in self._states:
            if label not in reachable:
                problems.append(f"state {label!r} can never be entered")
        if problems:
            raise ConsistencyError(self.name, problems)
        self._checked = True

    def _reachable(self) -> set[str]:
        if self._initial not in self._states:
            return set()
        seen: set[str] = set()
        todo = [self._initial]
        while todo:
            label = todo.pop()
            if label in seen or label not in self._states:
                continue
            seen.add(label)
            todo.extend(self._states[label].transitions.values())
        return seen

    # ------------------------------------------------------------------------ introspection
    def add_observer(self, observer: MachineObserver) -> None:
        self._observers.append(observer)

    def structure(self) -> StructureInfo:
        return StructureInfo(
            name=self.name,
            initial=self._initial or "",
            states=tuple(self._states),
            transitions=tuple(
                (label, outcome, target)
                for label, entry in self._states.items()
                for outcome, target in entry.transitions.items()
            ),
            outcomes=self.outcomes,
        )

    @property
    def active_state(self) -> str | None:
        """The label of the state running now (None when the machine is not running)."""
        return self._active

    def state(self, label: str) -> State:
        return self._states[label].state

    def _notify(self, call: Callable[[MachineObserver], None]) -> None:
        for observer in self._observers:
            call(observer)

    # ---------------------------------------------------------------------------- running
    def request_preempt(self) -> None:
        """Preempt the container and, cooperatively, the state running now."""
        super().request_preempt()
        if self._active is not None:
            self._states[self._active].state.request_preempt()

    async def execute(self, userdata: MutableMapping[str, Any] | None = None) -> str:
        if not self._checked:
            self.check()
        data = userdata if isinstance(userdata, UserData) else UserData(**dict(userdata or {}))
        structure = self.structure()
        self._notify(lambda o: o.on_structure(structure))
        label: str = self._initial  # type: ignore[assignment]
        self._previous = None
        transitions = 0
        views: dict[str, MutableMapping[str, Any]] = {}  # each state's window on ``data``, made once per run
        observers = self._observers
        try:
            while True:
                entry = self._states[label]
                self._active = label
                now = self.clock.now()
                for observer in observers:
                    observer.on_enter(self.name, label, now)
                view = views.get(label)
                if view is None:
                    view = views[label] = data.view(label, entry.state.input_keys, entry.state.output_keys)
                outcome = await entry.state.execute(view)
                if entry.state.preempt_requested:
                    entry.state.service_preempt()
                if outcome not in entry.state.outcomes:
                    raise RuntimeError(
                        f"state {label!r} of {self.name!r} returned {outcome!r}, not one of {entry.state.outcomes}"
                    )
                target = entry.transitions[outcome]
                if target == HISTORY:
                    if self._previous is None:
                        raise RuntimeError(f"state {label!r} of {self.name!r} returned to history, but there is none")
                    target = self._previous
                record = TransitionRecord(self.name, label, outcome, target, self.clock.now())
                for observer in observers:
                    observer.on_transition(record)
                transitions += 1
                if self.max_transitions is not None and transitions > self.max_transitions:
                    raise RuntimeError(f"state machine {self.name!r} exceeded {self.max_transitions} transitions")
                if target in self.outcomes:
                    if self.preempt_requested:
                        self.service_preempt()
                    return target
                self._previous, label = label, target
        finally:
            self._active = None
