"""Property tests of the loop expander on crafted XML: nested for_each and repeat expand to exactly the
operations a plain reference interpreter gives, in order, each with its iteration; whatever a loop's
``in``, a grid spec or a ``{variable}`` holds, the loader answers with located diagnostics, never a crash."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app_functions.registry import full_catalog
from execution_engine.app_model import ApplicationError, Diagnostic, load_application, validate_application

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
CATALOG = full_catalog()
SETTINGS = settings(suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow], deadline=None, max_examples=60)
_counter = itertools.count()


@dataclass
class Loop:
    kind: str  # for_each | repeat
    var: str
    values: list[str] = field(default_factory=list)  # for_each
    count: int = 0  # repeat
    body: list[Loop | int] = field(default_factory=list)  # an int: an operation, numbered


def steps(depth: int) -> st.SearchStrategy[list[Loop | int]]:
    operation = st.builds(lambda: next(_counter))
    if depth >= 3:
        return st.lists(operation, min_size=1, max_size=3)
    var = f"v{depth}"
    for_each = st.builds(lambda values, body: Loop("for_each", var, values=values, body=body),
                         st.lists(st.from_regex(r"[a-z][a-z0-9_]{0,5}", fullmatch=True), min_size=1, max_size=3, unique=True), st.deferred(lambda: steps(depth + 1)))
    repeat = st.builds(lambda count, body: Loop("repeat", var, count=count, body=body), st.integers(1, 3), st.deferred(lambda: steps(depth + 1)))
    return st.lists(st.one_of(operation, for_each, repeat), min_size=1, max_size=3)


def render(body: list[Loop | int], names: tuple[str, ...]) -> str:
    out = []
    for step in body:
        if isinstance(step, int):
            suffix = "".join(f"_{{{n}}}" for n in names)
            label = " ".join(f"{{{n}}}" for n in names) or "top"
            out.append(f'<operation id="o{step}{suffix}" name="{label}"><left_arm><function name="gripper_open"/></left_arm></operation>\n')
        elif step.kind == "for_each":
            out.append(f'<for_each var="{step.var}" in="{" ".join(step.values)}">\n{render(step.body, (*names, step.var))}</for_each>\n')
        else:
            out.append(f'<repeat count="{step.count}" var="{step.var}">\n{render(step.body, (*names, step.var))}</repeat>\n')
    return "".join(out)


def expected(body: list[Loop | int], env: dict[str, str], path: tuple[str, ...]) -> list[tuple[str, str, str]]:
    """(id, name, origin) of every operation, by a reference interpreter of the loops."""
    out: list[tuple[str, str, str]] = []
    for step in body:
        if isinstance(step, int):
            names = list(env)
            out.append((f"o{step}" + "".join(f"_{env[n]}" for n in names), " ".join(env[n] for n in names) or "top", " > ".join(path)))
            continue
        values = step.values if step.kind == "for_each" else [str(i) for i in range(1, step.count + 1)]
        for value in values:
            out += expected(step.body, {**env, step.var: value}, (*path, f"{step.kind} {step.var}={value}"))
    return out


def document(inner: str) -> str:
    return f'<?xml version="1.0"?>\n<application name="p" robot="nextage" cell="{CELL}">\n{inner}</application>\n'


@SETTINGS
@given(body=steps(0))
def test_nested_loops_expand_like_the_reference_interpreter(tmp_path: Path, body: list[Loop | int]) -> None:
    path = tmp_path / "loops.xml"
    path.write_text(document(render(body, ())))
    want = expected(body, {}, ())
    if len({i for i, _, _ in want}) != len(want):  # two values of a list alike after joining: refused, naming both
        found = validate_application(path, CATALOG)
        assert any("comes out the same in" in d.message for d in found)
        return
    application = load_application(path, CATALOG)
    assert [(o.id, o.name, o.origin) for o in application.operations] == want
    assert all(o.calls["left_arm"].function == "gripper_open" and o.calls["left_arm"].file == str(path) for o in application.operations)


def assert_located(found: list[Diagnostic], text: str) -> None:
    lines = text.count("\n") + 1
    assert found and all(1 <= d.line <= lines and d.col >= 1 and d.message for d in found)


_TEXT = st.text(st.characters(blacklist_categories=("Cs", "Cc")), max_size=40).map(lambda t: t.replace("&", "&amp;").replace("<", "&lt;").replace('"', "&quot;"))


@SETTINGS
@given(spec=_TEXT, prefix=st.sampled_from(["", "kind:", "grid:", "grid:rivet_1 ", "grid:rivet_1 2x2 "]), value=_TEXT)
def test_any_loop_list_grid_or_variable_gives_diagnostics_not_exceptions(tmp_path: Path, spec: str, prefix: str, value: str) -> None:
    inner = (f'<for_each var="s" in="{prefix}{spec}x">\n<operation id="p_{{s}}">'
             f'<right_arm><function name="pick_rivet"><params><param value="{{s}}{value}"/><param value="ref_R10"/></params></function></right_arm>'
             "</operation>\n</for_each>\n<operation id=\"put_back\"><right_arm><function name=\"gripper_open\"/></right_arm></operation>\n")
    text = document(inner)
    path = tmp_path / "crafted.xml"
    path.write_text(text)
    found = validate_application(path, CATALOG)
    if any(d.is_error for d in found):
        assert_located(found, text)
        with pytest.raises(ApplicationError):
            load_application(path, CATALOG)
    else:
        assert load_application(path, CATALOG).operations[-1].id == "put_back"


@SETTINGS
@given(edges=st.lists(st.lists(st.integers(0, 3), max_size=2), min_size=4, max_size=4), own=st.lists(st.integers(0, 2), min_size=4, max_size=4))
def test_any_call_graph_expands_or_names_its_cycle(tmp_path: Path, edges: list[list[int]], own: list[int]) -> None:
    """Four files, each with some operations and calls of the others (cycles included): a graph without a
    cycle from the first file expands to every operation of every path through it, in order; one with a
    cycle is refused naming it, never a hang or a crash."""
    folder = tmp_path / f"g{next(_counter)}"
    folder.mkdir()
    for index, (calls, operations) in enumerate(zip(edges, own)):
        body = "".join(f'<operation id="f{index}_{k}_{{p}}"><left_arm><function name="gripper_open"/></left_arm></operation>\n' for k in range(operations))
        body += "".join(f'<call application="f{callee}.xml"><param name="p" value="{{p}}.{index}-{j}"/></call>\n' for j, callee in enumerate(calls))
        (folder / f"f{index}.xml").write_text(document(body or '<operation id="e{p}"><left_arm><function name="gripper_open"/></left_arm></operation>\n'))
    main = folder / "main.xml"
    main.write_text(document('<call application="f0.xml"><param name="p" value="m"/></call>\n'))

    def ids(index: int, p: str, chain: tuple[int, ...]) -> list[str] | None:
        if index in chain:
            return None  # a cycle
        out = [f"f{index}_{k}_{p}" for k in range(own[index])] or ([f"e{p}"] if not edges[index] else [])
        for j, callee in enumerate(edges[index]):
            inner = ids(callee, f"{p}.{index}-{j}", (*chain, index))
            if inner is None:
                return None
            out += inner
        return out

    want = ids(0, "m", ())
    found = validate_application(main, CATALOG)
    if want is None:
        assert any(d.message.startswith("call cycle: ") for d in found)
    elif not want:
        assert found  # nothing to run: the schema's at least one operation is not met somewhere, or an empty body
    else:
        application = load_application(main, CATALOG)
        assert [o.id for o in application.operations] == want
