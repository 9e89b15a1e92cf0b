"""Outcome branches from outside (issue 24 item 2): any tree of <if>, <else> and operations is read into
the conditions a reference reading gives, or refused in lines that each name the file, line and column --
and the dry run's passes meet every set of conditions an operation is under (hypothesis)."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app_functions.registry import full_catalog
from cell_runner.dry_run.branches import assumptions
from execution_engine.app_model import read_application
from execution_engine.app_model.model import Condition

ROOT = Path(__file__).resolve().parent.parent
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
CATALOG = full_catalog()
OUTCOMES = ("found", "not_found", "in_range")  # in_range: not an outcome of locate


@dataclass
class Op:
    pass


@dataclass
class If:
    back: int  # tests the operation this many before the last one written before it (modulo how many there are)
    later: bool  # ... or, to be refused, one written after it
    outcome: str
    body: list[object] = field(default_factory=list)
    orelse: list[object] | None = None


@dataclass
class Else:
    """An <else> written on its own: refused, unless the <if> right before it has none (then it is that one's)."""

    body: list[object] = field(default_factory=list)


def trees() -> st.SearchStrategy[list[object]]:
    """Mostly well-formed trees (every branch on an operation before it), a fault mixed in now and then:
    a branch on a later operation or on an outcome locate does not have, an <else> on its own."""
    def compound(inner: st.SearchStrategy[object]) -> st.SearchStrategy[object]:
        body = st.lists(inner, min_size=1, max_size=3)
        good = st.builds(If, st.integers(0, 5), st.just(False), st.sampled_from(OUTCOMES[:2]), body, st.one_of(st.none(), body))
        bad = st.builds(If, st.integers(0, 5), st.booleans(), st.sampled_from(OUTCOMES), body, st.one_of(st.none(), body))
        stray = st.builds(Else, st.lists(inner, min_size=1, max_size=2))
        return st.integers(0, 13).flatmap(lambda k: good if k < 12 else bad if k == 12 else stray)  # one fault in 7

    first = st.integers(0, 9).map(lambda k: [Op()] if k else [])  # most files look at something before they branch on it
    return st.tuples(first, st.lists(st.recursive(st.just(Op()), compound, max_leaves=12), min_size=1, max_size=6)).map(lambda t: [*t[0], *t[1]])


@dataclass
class Rendered:
    lines: list[str] = field(default_factory=list)
    expected: list[tuple[str, tuple[Condition, ...]]] = field(default_factory=list)
    valid: bool = True


def possible(when: tuple[Condition, ...]) -> bool:
    """Whether the conditions can all hold (locate ends found or not_found)."""
    return all(any(all(c.met(outcome) for c in when if c.operation == key) for outcome in OUTCOMES[:2]) for key in {c.operation for c in when})


def render(steps: list[object], out: Rendered, when: tuple[Condition, ...] = (), indent: int = 1) -> None:
    """The XML of ``steps`` and, as a reference reading of it, the operations with their conditions."""
    pad = "  " * indent
    previous: If | None = None  # an <if> just written without an <else>: a stray <else> right after it is its else
    for step in steps:
        last, previous = previous, None
        if isinstance(step, Op):
            n = len(out.expected)
            out.valid &= possible(when)  # an operation no outcome lets run is refused
            out.expected.append((f"op_{n}", when))
            out.lines.append(f'{pad}<operation id="op_{n}"><left_arm><function name="locate"><params><param value="drill_1"/></params></function></left_arm></operation>')
        elif isinstance(step, If):
            count = len(out.expected)
            target = count + 3 if step.later or not count else count - 1 - step.back % count
            out.valid &= not (step.later or not count) and step.outcome != "in_range"
            condition = Condition(f"op_{target}", "left_arm", step.outcome)
            out.lines.append(f'{pad}<if group="left_arm" operation="op_{target}" outcome="{step.outcome}">')
            render(step.body, out, (*when, condition), indent + 1)
            out.lines.append(f"{pad}</if>")
            if step.orelse is not None:
                out.lines.append(f"{pad}<else>")
                render(step.orelse, out, (*when, Condition(condition.operation, "left_arm", step.outcome, False)), indent + 1)
                out.lines.append(f"{pad}</else>")
            else:
                previous = step
                step.tested = condition  # type: ignore[attr-defined]
        else:
            assert isinstance(step, Else)
            out.lines.append(f"{pad}<else>")
            if last is None:
                out.valid = False
                render(step.body, out, when, indent + 1)
            else:  # the else of the <if> right before it
                tested: Condition = last.tested  # type: ignore[attr-defined]
                render(step.body, out, (*when, Condition(tested.operation, "left_arm", tested.outcome, False)), indent + 1)
            out.lines.append(f"{pad}</else>")


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(steps=trees())
def test_any_tree_of_branches_is_read_as_the_reference_reads_it_or_refused_at_its_lines(tmp_path: Path, steps: list[object]) -> None:
    rendered = Rendered()
    render(steps, rendered)
    path = tmp_path / "branches.xml"
    path.write_text(f'<?xml version="1.0"?>\n<application name="b" robot="nextage" cell="{CELL}">\n' + "\n".join(rendered.lines) + "\n</application>\n")
    expected, valid = rendered.expected, rendered.valid
    app, diagnostics = read_application(path, CATALOG)
    errors = [d for d in diagnostics if d.severity == "error"]
    if not valid:
        assert app is None and errors
        for d in errors:
            text = f"{d.file}:{d.line}:{d.col}: {d.message}"
            assert "\n" not in text and re.match(rf"{re.escape(str(path))}:\d+:\d+: ", text), text
        return
    assert app is not None, [str(d) for d in errors]
    assert [(op.id, op.when) for op in app.operations] == expected
    passes = assumptions(app, CATALOG)
    for operation in app.operations:
        assert any(all(c.met(p.get((c.operation, c.group))) for c in operation.when) for p in passes), operation.when
