"""What a run of an application came to: the summary an operator reads and the CLI's exit code."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

RunOutcome = Literal["finished", "failed", "stopped"]


@dataclass(frozen=True)
class GroupError:
    """One failed function, as the machine reported it."""

    group: str
    operation: str
    function: str
    error: str
    attempt: int
    t: float


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
    finished_cleanly: bool = False  # every group reached Finish

    @property
    def total(self) -> float:
        return self.t_end - self.t_start

    @property
    def ok(self) -> bool:
        """Finished, every group in Finish; errors recovered by a retry do not spoil a run."""
        return self.outcome == "finished" and self.finished_cleanly

    def summary_lines(self) -> list[str]:
        lines = [
            f"application {self.app}: {self.outcome.upper()}" + (f" - {self.message}" if self.message else ""),
            f"  operations: {self.operations_done}/{self.operations_total}",
        ]
        for group in sorted(self.group_busy):
            busy = self.group_busy[group]
            share = 100.0 * busy / self.total if self.total > 0 else 0.0
            lines.append(f"  {group:<12} busy {busy:8.2f} s ({share:5.1f} %), {self.group_functions.get(group, 0)} functions")
        lines.append(f"  total        {self.total:8.2f} s")
        if self.retries:
            lines.append(f"  retries: {self.retries}")
        for err in self.errors:
            lines.append(f"  error: {err.group} operation {err.operation} {err.function} (attempt {err.attempt}) at {err.t:.2f} s: {err.error}")
        if self.safe_pose:
            lines.append(f"  robot sent to safe pose {self.safe_pose!r}")
        if not self.finished_cleanly:
            lines.append("  not every group reached Finish")
        return lines
