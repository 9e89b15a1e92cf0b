"""What a run of an application came to: the summary an operator reads and the CLI's exit code.

Besides times and errors, the report says what recovery did and who intervened: each error
says whether it was retried (and why not), the safe pose lists every retreat, speed and move
with its outcome -- a move that failed is not reported as "sent to the safe pose" -- and every
operator command is listed with its run time and its source.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from core_functions.printable import printable
from execution_engine.engine.waits import FlagWait, costliest, wait_totals

RunOutcome = Literal["finished", "failed", "stopped"]
StepOutcome = Literal["done", "skipped", "failed"]


@dataclass(frozen=True)
class GroupError:
    """One failed function, as the machine reported it, and what the error policy did about it."""

    group: str
    operation: str
    function: str
    error: str
    attempt: int
    t: float
    fault: str | None = None  # the FaultKind's value, e.g. "joint_limit"
    recovery: str = ""  # "retried: timeout is transient", "not retried: joint_limit is deterministic", ...


@dataclass(frozen=True)
class OperatorAction:
    """One operator command the engine received: when, what, from where, and what came of it."""

    t: float
    command: str
    source: str  # "terminal console (key p)", "service /execution_engine/pause", "safety stop on /cell/safety_stop"
    state: str  # the engine state the command arrived in ("alarm": an answer to the alarm)
    accepted: bool
    answer: str
    target: str = ""  # a breakpoint or run-to command: the operation it names (its id)


@dataclass(frozen=True)
class BreakpointHit:
    """The run paused before an operation (engine/breakpoints.py): a breakpoint, the run-to target or a step's end."""

    t: float
    operation: str
    kind: str  # break, run_to, step
    groups: tuple[str, ...]  # the groups that held there (every group in lock-step)
    message: str
    held: bool = True  # False: passed, no operator could have continued the run


@dataclass(frozen=True)
class SafePoseStep:
    """One step of the way to the safe pose for one group."""

    group: str
    step: Literal["retreat", "speed", "move"]
    outcome: StepOutcome
    detail: str


@dataclass
class RunReport:
    app: str
    operations_total: int
    outcome: RunOutcome = "finished"
    message: str = ""
    operations_done: int = 0
    t_start: float = 0.0
    t_end: float = 0.0
    group_busy: dict[str, float] = field(default_factory=dict)
    group_functions: dict[str, int] = field(default_factory=dict)
    errors: list[GroupError] = field(default_factory=list)
    retries: int = 0
    safe_pose: str | None = None  # the pose the robot was sent to after a failure, if any
    safe_pose_steps: list[SafePoseStep] = field(default_factory=list)
    operator_actions: list[OperatorAction] = field(default_factory=list)
    finished_cleanly: bool = False  # every group reached Finish
    flag_waits: list[FlagWait] = field(default_factory=list)  # every wait for a flag or a zone (engine/flags.py)
    #: The named outcome of every function an <if> tests, by "operation/group" (a vision fault so
    #: ended is an outcome, not an error: a hole not found, reported here).
    outcomes: dict[str, str] = field(default_factory=dict)
    #: What a fault outcome said, by the same key: why the hole was not found, what was measured.
    outcome_details: dict[str, str] = field(default_factory=dict)
    #: Operations an <if>/<else> left out, with the condition that was not met.
    skipped: list[tuple[str, str]] = field(default_factory=list)
    #: Every pause before an operation at a breakpoint, a run-to target or a step (engine/breakpoints.py).
    breakpoints: list[BreakpointHit] = field(default_factory=list)
    edits: list[str] = field(default_factory=list)  # each swap of a paused run's remainder (engine/remainder_swap.py), its line

    @property
    def total(self) -> float:
        return self.t_end - self.t_start

    @property
    def ok(self) -> bool:
        """Finished, every group in Finish; errors recovered by a retry do not spoil a run."""
        return self.outcome == "finished" and self.finished_cleanly

    @property
    def safe_pose_missed(self) -> list[str]:
        """Groups sent to the safe pose that did not get there."""
        moved = {s.group for s in self.safe_pose_steps if s.step == "move" and s.outcome == "done"}
        return sorted({s.group for s in self.safe_pose_steps} - moved)

    def summary_lines(self, iterations: Mapping[str, str] | None = None) -> list[str]:
        """The summary; ``iterations`` (``Application.iterations``) names the loop iteration or call of an
        error's operation."""
        iterations = iterations or {}
        lines = [
            f"application {self.app}: {self.outcome.upper()}" + (f" - {self.message}" if self.message else ""),
            f"  operations: {self.operations_done}/{self.operations_total}",
        ]
        for group in sorted(self.group_busy):
            busy = self.group_busy[group]
            share = 100.0 * busy / self.total if self.total > 0 else 0.0
            lines.append(f"  {group:<12} busy {busy:8.2f} s ({share:5.1f} %), {self.group_functions.get(group, 0)} functions")
        lines.append(f"  total        {self.total:8.2f} s")
        lines += self.wait_lines()
        if self.retries:
            lines.append(f"  retries: {self.retries}")
        for err in self.errors:
            recovery = f" - {err.recovery}" if err.recovery else ""
            made = f" ({iterations[err.operation]})" if err.operation in iterations else ""
            lines.append(f"  error: {err.group} operation {err.operation}{made} {err.function} (attempt {err.attempt}) at {err.t:.2f} s: {err.error}{recovery}")
        lines += self.branch_lines(iterations)
        lines += [f"  {edit}" for edit in self.edits]
        lines += self._safe_pose_lines()
        for hit in self.breakpoints:
            lines.append(f"  breakpoint at {hit.t:.2f} s: {hit.message}")
        for action in self.operator_actions:
            answer = "accepted" if action.accepted else "refused"
            target = f" {action.target}" if action.target else ""
            lines.append(f"  operator: {action.command}{target} at {action.t:.2f} s from {action.source} (in {action.state}): {answer} - {action.answer}")
        if not self.finished_cleanly:
            lines.append("  not every group reached Finish")
        return [printable(line) for line in lines]  # ids, names and peers' texts: no control or bidi character reaches the console

    def branch_lines(self, iterations: Mapping[str, str]) -> list[str]:
        """What each tested function ended with (a hole not found is named here) and what its branch left out."""
        lines = []
        for key, outcome in self.outcomes.items():
            operation, _, group = key.rpartition("/")
            made = f" ({iterations[operation]})" if operation in iterations else ""
            detail = self.outcome_details.get(key)
            lines.append(f"  outcome: {group} operation {operation}{made}: {outcome}" + (f" - {detail}" if detail else ""))
        if self.skipped:
            lines.append(f"  left out by their branch: {len(self.skipped)} operation(s): " + ", ".join(op for op, _ in self.skipped))
        return lines

    def wait_lines(self) -> list[str]:
        """Each group's idle time split into its waits for flags and zones and the rest; the costliest waits."""
        if not self.flag_waits:
            return []
        lines = []
        for group in sorted(self.group_busy):
            idle = max(0.0, self.total - self.group_busy[group])
            waited = wait_totals(self.flag_waits, group)
            if not waited:
                continue
            parts = ", ".join(f"{t:.2f} s waiting for {kind} {name!r}" for (kind, name), t in costliest(waited))
            lines.append(f"  {group:<12} idle {idle:8.2f} s: {parts}, {max(0.0, idle - sum(waited.values())):.2f} s the rest")
        costly = costliest(wait_totals(self.flag_waits), 3)
        lines.append("  waits that cost most: " + ", ".join(f"{kind} {name!r} {t:.2f} s" for (kind, name), t in costly))
        return lines

    def _safe_pose_lines(self) -> list[str]:
        if not self.safe_pose:
            return []
        missed = self.safe_pose_missed
        if not self.safe_pose_steps:
            head = f"  safe pose {self.safe_pose!r}: no group was moved"
        elif missed:
            head = f"  safe pose {self.safe_pose!r} NOT reached by {', '.join(missed)}"
        else:
            head = f"  robot at safe pose {self.safe_pose!r}"
        return [head] + [f"    {s.group:<12} {s.step:<8} {s.outcome}: {s.detail}" for s in self.safe_pose_steps]
