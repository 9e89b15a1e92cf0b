"""Loops and calls, expanded when the file is read into the flat operations everything else runs.

``<for_each>``, ``<repeat>`` and ``<call>`` exist only in the file: the reader keeps them as steps
(:class:`~execution_engine.app_model.reader.LoopSite`, ``CallBlockSite``) and this module turns
them into one operation per iteration, ``{var}`` substituted in the operation's id and name and in
every param value.  The checks, the engine, the group machines, the dry run, the checkpoint and the
trace then see an ordinary application -- each operation keeps where it was written (the line
inside the loop, the called file's own) and the iteration it was made for
(:class:`~execution_engine.app_model.expanded_source.ExpandedSource`), so every message names both.

Bounds, each refused at the line of the loop or call at fault: at most :data:`MAX_OPERATIONS`
operations in all, loops and calls at most :data:`MAX_DEPTH` deep, no call of a file that is
already being called (a cycle, named), a ``{var}`` no loop or call around it defines, an
operation id that comes out the same in two iterations.
"""
from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

from core_functions.printable import printable, unsafe_character
from core_functions.robots import RobotModel
from execution_engine.app_model.cell_model import Cell, Frame
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, in_iteration
from execution_engine.app_model.expanded_source import ExpandedSource
from execution_engine.app_model.grid import PREFIX as GRID, GridError, grid_frames, parse_grid
from execution_engine.app_model.positions import SourceMap
from execution_engine.app_model.model import Condition
from execution_engine.app_model.reader import INDEX, ApplicationDraft, CallBlockSite, CallSite, IfSite, LoopSite, OperationSite, Step

#: Operations an application may expand to: ten times the largest application measured
#: (docs/benchmarks.md), and a hundred thousand lines of a run report.
MAX_OPERATIONS = 100_000
#: Loops and calls inside each other: a pallet's layers, rows and columns, a block, its sub-block.
MAX_DEPTH = 8
#: Characters substitution may make in all (ids, names, values): what a 32 MiB file could hold, twice.
#: Without it a value of many {var}s over long values, in many iterations, could take gigabytes.
MAX_TEXT = 64 * 1024 * 1024
#: What a substituted text may hold at most, as application.xsd holds what is written.
_LONGEST = {"id": 64, "name": 256, "value": 4096, "in": 65536}
_KIND = "kind:"
_VARIABLE = re.compile(r"\{\{|\}\}|\{([A-Za-z_][A-Za-z0-9_.\-]*)\}")  # a name as application.xsd's identifier
_SEPARATORS = re.compile(r"[\s,]+")

#: Reads a called application: (its path, how messages show it) -> its draft (None: unreadable,
#: the problems in the log given).
ReadCalled = Callable[[Path, str, DiagnosticLog], "ApplicationDraft | None"]


@dataclass(frozen=True)
class _Unit:
    """A file whose steps are being expanded: its text, where it is, how messages name it."""

    source: SourceMap
    path: Path
    display: str


class _TooLarge(Exception):
    """The expansion passed MAX_OPERATIONS: the loop that did it has been reported."""


def substitute(text: str, env: Mapping[str, str]) -> tuple[str, list[str]]:
    """``text`` with every ``{name}`` of ``env`` replaced (``{{`` and ``}}`` stand for a brace),
    and the names it uses that ``env`` does not define."""
    if "{" not in text and "}" not in text:
        return text, []
    unknown: list[str] = []

    def one(match: re.Match[str]) -> str:
        name = match.group(1)
        if name is None:
            return match.group(0)[0]
        if name in env:
            return env[name]
        unknown.append(name)
        return match.group(0)

    return _VARIABLE.sub(one, text), unknown


def variables(text: str) -> list[str]:
    """The ``{name}`` variables ``text`` uses."""
    return [m.group(1) for m in _VARIABLE.finditer(text) if m.group(1)]


class Expander:
    """Expands a draft's steps into its operations (``expand``), reporting into ``log``."""

    def __init__(
        self, draft: ApplicationDraft, cell: Cell | None, cell_broken: bool, log: DiagnosticLog, read_called: ReadCalled,
        path: Path,
    ) -> None:
        self.draft = draft
        self.cell = cell
        self.cell_broken = cell_broken
        self.log = log
        self.read_called = read_called
        main = draft.source
        assert isinstance(main, SourceMap)
        self.source = ExpandedSource(main)
        self.main = _Unit(main, path.resolve(), main.file)
        self.operations: list[OperationSite] = []
        self.ids: dict[str, OperationSite] = {}
        self.reported: set[tuple[int, int]] = set()
        self.extra_frames: dict[str, Frame] = {}
        self.called: dict[Path, tuple[_Unit, ApplicationDraft] | None] = {}
        self.includes: list[Path] = []
        self.refused: set[Path] = set()  # called files refused with their reason (robot, cell) already given
        #: Where a {variable} could not be substituted: the catalog's check of what is left there
        #: would only repeat the problem (merge_iterations drops it).
        self.unsubstituted: set[tuple[str, int, int]] = set()
        self.made_text = 0  # characters substitution made so far (MAX_TEXT)
        #: The <if>/<else> around the operations being expanded, outermost first.
        self.when: tuple[Condition, ...] = ()
        #: Every <if> expanded: (its offset, its condition, the operation it tests) -- the catalog's
        #: check of the outcome (app_model.branches) comes after the functions are checked.
        self.branches: list[tuple[int, Condition, OperationSite]] = []

    # ------------------------------------------------------------------ reporting
    def error(self, offset: int, message: str, severity: str = "error") -> None:
        if self.log.full:
            self.log.count("warning" if severity == "warning" else "error")
            return
        self.log.append(Diagnostic.at(self.source.at_offset(offset), message, "warning" if severity == "warning" else "error"))

    def attribute(self, offset: int, name: str) -> int:
        return self.source.attribute_offset(offset, name)

    # ------------------------------------------------------------------ the whole body
    def expand(self) -> tuple[list[OperationSite], Cell | None]:
        """The operations of every iteration, in order, and the cell with the grids' frames."""
        try:
            self.steps(self.draft.body, {}, self.main, (), 0, (self.main.path,), ())
        except _TooLarge:
            pass
        cell = self.cell
        if cell is not None and self.extra_frames:
            cell = replace(cell, frames={**cell.frames, **self.extra_frames})
        return self.operations, cell

    def steps(
        self, steps: list[Step], env: Mapping[str, str], unit: _Unit, path: tuple[str, ...], depth: int, chain: tuple[Path, ...],
        named: tuple[tuple[str, int], ...],
    ) -> None:
        base = self.source.base(unit.source, " > ".join(path))
        for step in steps:
            if isinstance(step, OperationSite):
                self.operation(step, env, base, path)
            elif isinstance(step, LoopSite):
                self.loop(step, env, unit, path, depth + 1, chain, named, base)
            elif isinstance(step, IfSite):
                self.branch(step, env, unit, path, depth, chain, named, base)
            else:
                self.call(step, env, unit, path, depth + 1, chain, base)

    # ------------------------------------------------------------------ operations
    def operation(self, site: OperationSite, env: Mapping[str, str], base: int, path: tuple[str, ...]) -> None:
        if len(self.operations) >= MAX_OPERATIONS:
            self.error(base + site.at, f"the application expands to more than {MAX_OPERATIONS:,} operations here, the limit")
            raise _TooLarge
        op_id = self.text(site.id, env, base + site.at, "id", "operation id")
        name = self.text(site.name, env, base + site.at, "name", "operation name") if site.name is not None else None
        calls: dict[str, CallSite] = {}
        for group, call in site.calls.items():
            values = tuple(
                self.text(value, env, base + at, "value", f"param {i + 1} of {call.function}")
                for i, (value, at) in enumerate(zip(call.values, call.param_at))
            )
            calls[group] = CallSite(call.group, call.function, values, tuple(base + at for at in call.param_at), base + call.at, call.names, call.implicit)
        made = OperationSite(op_id, name, base + site.at, calls, self.when, site.breakpoint)
        first = self.ids.get(op_id)
        if first is None:
            self.ids[op_id] = made
        elif path or self.source.context(first.at):  # two top-level operations: the reader said so
            self.duplicate(made, first, site, self.source.block(base)[0])
        self.operations.append(made)

    def text(self, text: str, env: Mapping[str, str], tag: int, attribute: str, what: str) -> str:
        out, unknown = substitute(text, env)
        if out is not text:
            self.made_text += len(out)
            if self.made_text > MAX_TEXT:
                self.error(self.attribute(tag, attribute), f"substituting the loops' variables makes more than {MAX_TEXT:,} characters of text, the limit")
                raise _TooLarge
            self.check_made(out, text, tag, attribute, what)
        if unknown:
            where = self.source.at_offset(self.attribute(tag, attribute))
            self.unsubstituted.add((where.file, where.line, where.col))
        for name in dict.fromkeys(unknown):
            known = ", ".join(sorted(env))
            defined = f"the variables here: {known}" if known else (
                "no loop or call around it defines any (a library block is checked through the application that calls it)")
            self.error(self.attribute(tag, attribute), f"unknown variable {{{name}}} in {what} {text!r}: {defined}")
        return out

    def check_made(self, out: str, text: str, tag: int, attribute: str, what: str) -> None:
        """What substitution made holds to what the schema holds a written text to (length; an id
        also: no spaces, nothing that would make it look like another on a console)."""
        longest = _LONGEST.get(attribute, 4096)
        if len(out) > longest:
            self.error(self.attribute(tag, attribute), f"{what} {text!r} comes out {len(out):,} characters long, more than {longest:,}")
        elif attribute == "id":
            unsafe = None if out.isascii() and out.isprintable() else unsafe_character(out)
            if unsafe is None and (not out or any(c.isspace() for c in out)):
                unsafe = "a space" if out else "nothing"
            if unsafe is not None:
                self.error(self.attribute(tag, attribute), f"{what} {text!r} comes out '{printable(out)}', which holds {unsafe}; "
                           "an id needs letters, digits and punctuation")

    def duplicate(self, made: OperationSite, first: OperationSite, site: OperationSite, source: SourceMap) -> None:
        """Reported once per ``<operation>`` written, at its id (without the iteration: both are named)."""
        key = (id(source), site.at)
        if key in self.reported:
            return
        self.reported.add(key)
        first_where = self.source.at_offset(first.at)
        first_context = first_where.context or "the top of the file"
        here = self.source.context(made.at) or "the top of the file"
        plain = self.source.base(source, "") + site.at
        self.error(self.attribute(plain, "id"), (
            f"operation id {made.id!r} comes out the same in {first_context} ({first_where.file}:{first_where.line}) and in {here}: "
            "put a loop variable in the id (id=\"insert_{hole}\") so every iteration has its own"
        ))

    # ------------------------------------------------------------------ branches
    def branch(
        self, site: IfSite, env: Mapping[str, str], unit: _Unit, path: tuple[str, ...], depth: int, chain: tuple[Path, ...],
        named: tuple[tuple[str, int], ...], base: int,
    ) -> None:
        """The <if>'s operations under its condition, the <else>'s under the opposite one.  The
        operation it tests must come before it (in this iteration or an earlier one) and give
        the group a function: an outcome is known only once that function has ended."""
        at = base + site.at
        tested_id = self.text(site.operation, env, at, "operation", "the <if>'s operation")
        tested = self.ids.get(tested_id)
        if tested is None:
            before = [op.id for op in self.operations[-5:]]
            self.error(self.attribute(at, "operation"), (
                f"<if> tests operation {tested_id!r}, which does not come before it: an outcome is known only once its "
                f"operation has run (the last ones before here: {', '.join(before) or 'none'})"
            ))
        elif self.draft.robot is not None and site.group not in self.draft.robot.group_names:
            self.error(self.attribute(at, "group"), f"<if> names group {site.group!r}, which {self.draft.robot.name} does not have "
                       f"(its groups: {', '.join(self.draft.robot.group_names)})")
            tested = None
        elif site.group not in tested.calls or tested.calls[site.group].implicit or tested.calls[site.group].function == "wait":
            self.error(self.attribute(at, "group"), (
                f"<if> tests {site.group} in operation {site.operation!r}, where {site.group} runs no function "
                f"(only waits): name the group whose function's outcome chooses"
            ))
            tested = None
        condition = Condition(tested_id, site.group, site.outcome)
        if tested is not None:
            self.branches.append((at, condition, tested))
        outer = self.when
        try:
            self.when = (*outer, condition)
            self.steps(site.body, env, unit, path, depth, chain, named)
            if site.else_at is not None:
                self.when = (*outer, Condition(tested_id, site.group, site.outcome, holds=False))
                self.steps(site.orelse, env, unit, path, depth, chain, named)
        finally:
            self.when = outer

    # ------------------------------------------------------------------ loops
    def loop(
        self, loop: LoopSite, env: Mapping[str, str], unit: _Unit, path: tuple[str, ...], depth: int, chain: tuple[Path, ...],
        named: tuple[tuple[str, int], ...], base: int,
    ) -> None:
        at = base + loop.at
        plain = self.source.base(unit.source, "") + loop.at  # the same in every iteration around it: said once
        if depth > MAX_DEPTH:
            self.error(plain, f"<{loop.kind}> is nested {depth} deep in loops and calls, more than the limit of {MAX_DEPTH}")
            return
        taken = dict(named)
        for name in loop.named:
            if name in taken:
                where = "var" if name == loop.var else "index"
                self.error(self.attribute(plain, where), (
                    f"variable {{{name}}} is already the variable of the loop at line {self.source.at_offset(taken[name]).line}: "
                    "give this one another name"
                ))
                return
        values = self.values(loop, env, at)
        if values is None:
            return
        size = len(values) * self.size(loop.body, env, unit, chain, depth)
        if len(self.operations) + size > MAX_OPERATIONS:
            self.error(plain, (
                f"<{loop.kind}> expands to {size:,} operations ({len(values):,} iterations), which takes the application "
                f"past the limit of {MAX_OPERATIONS:,} operations"
            ))
            raise _TooLarge
        inner_named = named + tuple((name, at) for name in loop.named)
        for position, value in enumerate(values, start=1):
            inner = dict(env)
            if loop.kind == "for_each":
                inner[loop.index or INDEX] = str(position)
                inner[loop.var] = value
                label = f"for_each {loop.var}={value}"
            else:
                inner[loop.var] = str(position)
                label = f"repeat {loop.var}={position}"
            self.steps(loop.body, inner, unit, (*path, label), depth, chain, inner_named)

    def values(self, loop: LoopSite, env: Mapping[str, str], at: int) -> list[str] | None:
        """The values a loop takes, in order; None when they cannot be had (reported)."""
        if loop.kind == "repeat":
            return [str(i) for i in range(1, loop.count + 1)]
        written = self.text(loop.values, env, at, "in", "in")
        spec = written.strip()
        if spec.startswith(_KIND):
            return self.kind_values(spec[len(_KIND):].strip(), at)
        if spec.startswith(GRID):
            return self.grid_values(spec[len(GRID):].strip(), at)
        values = [v for v in _SEPARATORS.split(spec) if v]
        if not values:
            self.error(self.attribute(at, "in"), "in lists no values")
            return None
        return values

    def kind_values(self, kind: str, at: int) -> list[str] | None:
        if self.cell is None:
            if not self.cell_broken:
                self.error(self.attribute(at, "in"), f"in=\"kind:{kind}\" takes the cell's frames of that kind, but the application names no cell")
            return None
        frames = [name for name, frame in {**self.cell.frames, **self.extra_frames}.items() if frame.kind == kind]
        if not frames:
            kinds = ", ".join(sorted({frame.kind for frame in self.cell.frames.values()})) or "none"
            self.error(self.attribute(at, "in"), f"in=\"kind:{kind}\": the cell has no frame of kind {kind!r} (its kinds: {kinds})")
            return None
        return frames

    def grid_values(self, spec: str, at: int) -> list[str] | None:
        if self.cell is None:
            if not self.cell_broken:
                self.error(self.attribute(at, "in"), "in=\"grid:...\" makes frames under a frame of the cell, but the application names no cell")
            return None
        where = self.source.at_offset(self.attribute(at, "in"))
        try:
            made = grid_frames(spec, {**self.cell.frames, **self.extra_frames}, where)
        except GridError as error:
            self.error(self.attribute(at, "in"), f"in=\"grid:{spec}\": {error}")
            return None
        self.extra_frames.update(made)
        return list(made)

    def size(self, steps: list[Step], env: Mapping[str, str], unit: _Unit, chain: tuple[Path, ...], depth: int) -> int:
        """How many operations ``steps`` expand to (inner loops counted with their first values;
        nothing reported: expanding them reports)."""
        total = 0
        for step in steps:
            if isinstance(step, OperationSite):
                total += 1
            elif isinstance(step, IfSite):
                total += self.size(step.body, env, unit, chain, depth) + self.size(step.orelse, env, unit, chain, depth)
            elif depth >= MAX_DEPTH:
                continue
            elif isinstance(step, LoopSite):
                if step.kind == "repeat":
                    count = step.count
                else:
                    count = self.quiet_count(step, env)
                if count:
                    inner = dict(env)
                    inner.setdefault(step.var, "")
                    total += count * self.size(step.body, inner, unit, chain, depth + 1)
            else:
                called = self.load(step, unit, chain, self.source.base(unit.source, "") + step.at, quiet=True)
                if called is not None:
                    total += self.size(called[1].body, {}, called[0], (*chain, called[0].path), depth + 1)
            if total > MAX_OPERATIONS:
                return total
        return total

    def quiet_count(self, loop: LoopSite, env: Mapping[str, str]) -> int:
        spec = substitute(loop.values, env)[0].strip()
        if spec.startswith(_KIND):
            kind = spec[len(_KIND):].strip()
            return sum(1 for f in self.cell.frames.values() if f.kind == kind) if self.cell is not None else 0
        if spec.startswith(GRID):
            try:
                grid = parse_grid(spec[len(GRID):].strip())
            except GridError:
                return 0
            return grid.rows * grid.columns
        return sum(1 for v in _SEPARATORS.split(spec) if v)

    # ------------------------------------------------------------------ calls
    def call(self, call: CallBlockSite, env: Mapping[str, str], unit: _Unit, path: tuple[str, ...], depth: int, chain: tuple[Path, ...], base: int) -> None:
        at = base + call.at
        if depth > MAX_DEPTH:
            self.error(self.source.base(unit.source, "") + call.at, f"<call> is nested {depth} deep in loops and calls, more than the limit of {MAX_DEPTH}")
            return
        params: dict[str, str] = {}
        for name, value, param_at in call.params:
            if name in params:
                self.error(self.attribute(base + param_at, "name"), f"param {name!r} of the call is given twice")
                continue
            params[name] = self.text(value, env, base + param_at, "value", f"param {name!r} of the call")
        loaded = self.load(call, unit, chain, self.source.base(unit.source, "") + call.at)
        if loaded is None:
            return
        called, draft = loaded
        used = {name for step in draft.body for name in _step_variables(step)}
        for name, _, param_at in call.params:
            if name not in used:
                self.error(self.attribute(base + param_at, "name"), (
                    f"{call.application} uses no variable {{{name}}} (it uses: {', '.join(sorted(used)) or 'none'})"
                ), "warning")
        caller = self.source.at_offset(at)
        bound = " ".join(f"{k}={v}" for k, v in params.items())
        label = f"call {call.application}{' ' + bound if bound else ''} at {caller.file}:{caller.line}"
        size = self.size(draft.body, params, called, (*chain, called.path), depth)
        if len(self.operations) + size > MAX_OPERATIONS:
            self.error(at, f"<call> of {call.application} adds {size:,} operations, which takes the application past the limit of {MAX_OPERATIONS:,}")
            raise _TooLarge
        self.steps(draft.body, params, called, (*path, label), depth, (*chain, called.path), ())

    def load(self, call: CallBlockSite, unit: _Unit, chain: tuple[Path, ...], at: int, *, quiet: bool = False) -> tuple[_Unit, ApplicationDraft] | None:
        """The called application (read once), checked against the caller; None when it cannot be
        used (reported at the call ``at`` unless ``quiet``)."""
        path = (unit.path.parent / call.application).resolve()
        display = os.path.normpath(os.path.join(os.path.dirname(unit.display), call.application))
        if path in chain:
            if not quiet:
                names = " -> ".join(_shown(p, self.main) for p in (*chain[chain.index(path):], path))
                self.error(self.attribute(at, "application"), f"call cycle: {names}; an application cannot call itself, directly or through others")
            return None
        if path not in self.called:
            self.called[path] = self.read(path, display, at, call.application)
        loaded = self.called[path]
        if loaded is None and not quiet and path not in self.refused:
            self.error(self.attribute(at, "application"), f"called application {call.application} has errors (listed with its name)"
                       if path.is_file() else f"called application {call.application} not found (looked for {path})")
        return loaded

    def read(self, path: Path, display: str, at: int, shown: str) -> tuple[_Unit, ApplicationDraft] | None:
        """The called file read and checked against the caller (``shown``: its name as the call writes it)."""
        own = DiagnosticLog()
        draft = self.read_called(path, display, own) if path.is_file() else None
        caller = self.source.at_offset(at)
        suffix = in_iteration(f"called from {caller.file}:{caller.line}:{caller.col}")
        for diagnostic in own:
            self.log.append(replace(diagnostic, message=diagnostic.message + suffix))
        self.log.hidden_errors += own.hidden_errors
        self.log.hidden_warnings += own.hidden_warnings
        if draft is None or own.has_errors:
            return None
        robot: RobotModel | None = self.draft.robot
        if draft.robot is None or robot is None or draft.robot.name != robot.name:
            theirs = draft.robot.name if draft.robot is not None else "no robot"
            self.error(self.attribute(at, "application"), f"called application {shown} is for {theirs}, this one for {robot.name if robot else '?'}")
            self.refused.add(path)
            return None
        mine = self.draft.cell_path.resolve() if self.draft.cell_path is not None else None
        if draft.cell_path is not None and draft.cell_path.resolve() != mine:
            self.error(self.attribute(at, "application"), (
                f"called application {shown} names the cell {draft.cell_display}, this one {self.draft.cell_display or 'none'}: "
                "a called application works in the caller's cell (leave its cell= out, or name the same file)"
            ))
            self.refused.add(path)
            return None
        if draft.sync != self.draft.sync:
            self.error(self.attribute(at, "application"), (
                f"{shown} says sync=\"{draft.sync}\", this application sync=\"{self.draft.sync}\": its operations run as this one's do"
            ), "warning")
        if draft.policy is not None:
            self.error(self.attribute(at, "application"), f"the <error_policy> of {shown} does not apply: the calling application's does", "warning")
        source = draft.source
        assert isinstance(source, SourceMap)
        self.includes.append(path)
        return _Unit(source, path, display), draft


def _step_variables(step: Step) -> list[str]:
    if isinstance(step, OperationSite):
        texts = [step.id, step.name or ""] + [v for call in step.calls.values() for v in call.values]
        return [name for text in texts for name in variables(text)]
    if isinstance(step, IfSite):
        return variables(step.operation) + [name for s in (*step.body, *step.orelse) for name in _step_variables(s)]
    if isinstance(step, LoopSite):
        inner = [name for s in step.body for name in _step_variables(s)]
        return variables(step.values) + [n for n in inner if n not in step.named and n not in (step.var, step.index)]
    return [name for _, value, _ in step.params for name in variables(value)]


def _shown(path: Path, main: _Unit) -> str:
    try:
        return str(path.relative_to(main.path.parent))
    except ValueError:
        return str(path)


def merge_iterations(log: DiagnosticLog, contexts: list[str], unsubstituted: set[tuple[str, int, int]]) -> None:
    """One line for a problem found at one place in several iterations, naming them (a bad
    constant param in a loop of 40 is one mistake, not 40 lines); at a value whose {variable}
    is unknown, only that is said."""
    suffixes = {in_iteration(context) for context in contexts if context}
    merged: list[Diagnostic | tuple[Diagnostic, list[str]]] = []
    groups: dict[tuple[str, int, int, str, str], tuple[Diagnostic, list[str]]] = {}
    for diagnostic in log.kept:
        if (diagnostic.file, diagnostic.line, diagnostic.col) in unsubstituted and not diagnostic.message.startswith("unknown variable {"):
            continue
        cut = diagnostic.message.rfind(" (in ")
        if cut < 0 or diagnostic.message[cut:] not in suffixes:
            merged.append(diagnostic)
            continue
        message, context = diagnostic.message[:cut], diagnostic.message[cut + 5:-1]
        key = (diagnostic.file, diagnostic.line, diagnostic.col, diagnostic.severity, message)
        group = groups.get(key)
        if group is None:
            group = groups[key] = (replace(diagnostic, message=message), [])
            merged.append(group)
        group[1].append(context)
    kept: list[Diagnostic] = []
    for entry in merged:
        if isinstance(entry, Diagnostic):
            kept.append(entry)
            continue
        diagnostic, found = entry
        if len(found) == 1:
            named = found[0]
        elif len(found) <= 3:
            named = "; ".join(found)
        else:
            named = f"{len(found)} iterations: {'; '.join(found[:3])}; and {len(found) - 3} more"
        kept.append(replace(diagnostic, message=diagnostic.message + in_iteration(named)))
    log.kept = kept
