"""Problems found in an application or cell file, in the ``FILE:LINE:COL: message`` form editors jump to.

Every check appends to a list instead of raising, so a user sees every problem of a file in one
run (the paper's GUI avoided errors by construction; a hand-written file needs the next best thing).
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal

Severity = Literal["error", "warning"]


@dataclass(frozen=True, order=True)
class Location:
    """A 1-based line and column (in characters) of a file."""

    file: str
    line: int
    col: int


@dataclass(frozen=True)
class Diagnostic:
    """One problem: where it is and what is wrong, in plain words."""

    file: str
    line: int
    col: int
    message: str
    severity: Severity = "error"

    @staticmethod
    def at(where: Location, message: str, severity: Severity = "error") -> Diagnostic:
        return Diagnostic(where.file, where.line, where.col, message, severity)

    @property
    def is_error(self) -> bool:
        return self.severity == "error"

    def sort_key(self) -> tuple[str, int, int]:
        return (self.file, self.line, self.col)

    def __str__(self) -> str:
        prefix = "warning: " if self.severity == "warning" else ""
        return f"{self.file}:{self.line}:{self.col}: {prefix}{self.message}"


def sorted_diagnostics(diagnostics: Iterable[Diagnostic]) -> list[Diagnostic]:
    """By file, line, column; the same problem reported twice at one place is shown once."""
    seen: set[Diagnostic] = set()
    unique: list[Diagnostic] = []
    for diagnostic in diagnostics:
        if diagnostic not in seen:
            seen.add(diagnostic)
            unique.append(diagnostic)
    return sorted(unique, key=Diagnostic.sort_key)


def has_errors(diagnostics: Iterable[Diagnostic]) -> bool:
    return any(d.is_error for d in diagnostics)


class ApplicationError(Exception):
    """Loading failed; ``diagnostics`` holds every problem found, sorted, errors and warnings."""

    def __init__(self, diagnostics: Sequence[Diagnostic]) -> None:
        self.diagnostics: tuple[Diagnostic, ...] = tuple(sorted_diagnostics(diagnostics))
        errors = sum(1 for d in self.diagnostics if d.is_error)
        lines = "\n".join(str(d) for d in self.diagnostics)
        super().__init__(f"{errors} error(s)\n{lines}" if lines else "invalid file")
