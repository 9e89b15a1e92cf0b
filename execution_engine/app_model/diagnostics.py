"""Problems found in an application or cell file, in the ``FILE:LINE:COL: message`` form editors jump to.

Every check appends to a log instead of raising, so a user sees every problem of a file in one
run (the paper's GUI avoided errors by construction; a hand-written file needs the next best thing).
"Every" has a ceiling: a generated file can hold a million mistakes, and a million messages help
nobody and cost memory and time.  Each check keeps its first :data:`MAX_DIAGNOSTICS` and only
counts the rest (:class:`DiagnosticLog`); the report shows the first ``MAX_DIAGNOSTICS`` by
position and ends with "and N more problems" (:func:`capped`).
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal

from core_functions.printable import printable

Severity = Literal["error", "warning"]

#: At most this many diagnostics are shown for one validation; the rest are counted.
MAX_DIAGNOSTICS = 100


@dataclass(frozen=True, order=True)
class Location:
    """A 1-based line and column (in characters) of a file.

    ``context``: for a place inside a loop or a called application, which iteration of it
    (``for_each hole=drill_3``, ``call insert_block.xml hole=drill_3 at app.xml:20``): the same
    line stands for every iteration, so a message about one of them names it."""

    file: str
    line: int
    col: int
    context: str = field(default="", compare=False)


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
        if where.context:
            message = f"{message}{in_iteration(where.context)}"
        return Diagnostic(where.file, where.line, where.col, message, severity)

    @property
    def is_error(self) -> bool:
        return self.severity == "error"

    def sort_key(self) -> tuple[str, int, int]:
        return (self.file, self.line, self.col)

    def __str__(self) -> str:
        """The line a console shows: what came from the file with its control and bidi characters escaped."""
        prefix = "warning: " if self.severity == "warning" else ""
        return f"{printable(self.file)}:{self.line}:{self.col}: {prefix}{printable(self.message)}"


def in_iteration(context: str) -> str:
    """The words a message about one iteration ends with: `` (in for_each hole=drill_3)``."""
    return f" (in {context})"


@dataclass(frozen=True)
class Omitted(Diagnostic):
    """The last line of a capped report: how many problems were found and not shown."""

    hidden_errors: int = 0
    hidden_warnings: int = 0


class DiagnosticLog:
    """One check's diagnostics: the first ``keep`` are kept, the rest only counted.

    Past the limit a problem costs a counter, not a message; :attr:`full` lets a check skip work
    that only serves the message (locating it, looking for a 'did you mean').
    """

    def __init__(self, keep: int = MAX_DIAGNOSTICS) -> None:
        self.keep = keep
        self.kept: list[Diagnostic] = []
        self.hidden_errors = 0
        self.hidden_warnings = 0

    @property
    def full(self) -> bool:
        return len(self.kept) >= self.keep

    def count(self, severity: Severity = "error") -> None:
        """A problem found beyond the limit: counted, not described."""
        if severity == "error":
            self.hidden_errors += 1
        else:
            self.hidden_warnings += 1

    def append(self, diagnostic: Diagnostic) -> None:
        if isinstance(diagnostic, Omitted):  # a capped report merged into a larger one
            self.hidden_errors += diagnostic.hidden_errors
            self.hidden_warnings += diagnostic.hidden_warnings
            return
        if self.full:
            self.count(diagnostic.severity)
        else:
            self.kept.append(diagnostic)

    def extend(self, diagnostics: Iterable[Diagnostic]) -> None:
        for diagnostic in diagnostics:
            self.append(diagnostic)

    def merge(self, other: DiagnosticLog) -> None:
        self.extend(other.kept)
        self.hidden_errors += other.hidden_errors
        self.hidden_warnings += other.hidden_warnings

    @property
    def has_errors(self) -> bool:
        return self.hidden_errors > 0 or has_errors(self.kept)

    def __iter__(self) -> Iterator[Diagnostic]:
        return iter(self.kept)

    def __len__(self) -> int:
        return len(self.kept)


def capped(diagnostics: Iterable[Diagnostic], limit: int = MAX_DIAGNOSTICS) -> list[Diagnostic]:
    """Sorted and unique (:func:`sorted_diagnostics`), at most ``limit`` of them, then one
    :class:`Omitted` line saying how many more there are (counted ones of a
    :class:`DiagnosticLog` included).  The extra line sits at the first problem not shown, or at
    the last one shown, so the list stays sorted."""
    log = diagnostics if isinstance(diagnostics, DiagnosticLog) else None
    if log is None:
        log = DiagnosticLog(keep=2**62)  # only to add up the Omitted lines of capped reports
        log.extend(diagnostics)
    hidden_errors, hidden_warnings = log.hidden_errors, log.hidden_warnings
    ordered = sorted_diagnostics(log.kept)
    shown, rest = ordered[:limit], ordered[limit:]
    hidden_errors += sum(1 for d in rest if d.is_error)
    hidden_warnings += sum(1 for d in rest if not d.is_error)
    if not hidden_errors and not hidden_warnings:
        return shown
    anchor = rest[0] if rest else shown[-1] if shown else Diagnostic("?", 1, 1, "")
    total = hidden_errors + hidden_warnings
    parts = [f"{n:,} {word}{'s' if n != 1 else ''}" for n, word in ((hidden_errors, "error"), (hidden_warnings, "warning")) if n]
    message = (f"and {total:,} more problem{'s' if total != 1 else ''} ({', '.join(parts)}) not shown: "
               f"the report stops after {limit}; fix these and validate again")
    severity: Severity = "error" if hidden_errors else "warning"
    return [*shown, Omitted(anchor.file, anchor.line, anchor.col, message, severity, hidden_errors, hidden_warnings)]


def count_problems(diagnostics: Iterable[Diagnostic]) -> tuple[int, int]:
    """(errors, warnings) of a report, the ones an :class:`Omitted` line stands for included."""
    errors = warnings = 0
    for diagnostic in diagnostics:
        if isinstance(diagnostic, Omitted):
            errors += diagnostic.hidden_errors
            warnings += diagnostic.hidden_warnings
        elif diagnostic.is_error:
            errors += 1
        else:
            warnings += 1
    return errors, warnings


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
        self.diagnostics: tuple[Diagnostic, ...] = tuple(capped(diagnostics))
        errors = count_problems(self.diagnostics)[0]
        lines = "\n".join(str(d) for d in self.diagnostics)
        super().__init__(f"{errors} error(s)\n{lines}" if lines else "invalid file")
