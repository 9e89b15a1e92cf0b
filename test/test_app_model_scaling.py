"""Validation work grows linearly with the input, whatever the input: counted, not timed.

Each test counts the work of one suspect -- parent look-ups of the frame tree, pose products,
'did you mean' comparisons, the elements and sibling lists handed to libxml2, the nodes of the
parsed tree -- and checks it against the size of the input.  The files are the ones that hung
the validator: a 5,000-frame parent chain (cubic), 100,000 unknown frames against a 200,000-frame
cell (a search of the whole cell for each), floods of unknown elements and of comments.
"""
from __future__ import annotations

import dataclasses
import difflib
import random
import tracemalloc
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

import pytest
from app_model_support import APP_XML, CELL_XML, small_catalog
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from core_functions.geometry import Pose
from execution_engine.app_model import MAX_DIAGNOSTICS, MAX_ELEMENTS, Omitted, count_problems, validate_application, validate_cell
from execution_engine.app_model import safe_xml, structure, validation
from execution_engine.app_model.frame_tree import WORLD, order_frames
from execution_engine.app_model.safe_xml import MAX_ATTRIBUTES, read_xml
from execution_engine.app_model.schema import SchemaInfo

T = TypeVar("T")
CATALOG = small_catalog()
SETTINGS = settings(suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow], deadline=None, max_examples=25)


class CountingParents(Mapping[str, str]):
    """A frame -> parent map that counts look-ups: the work of ordering a frame tree."""

    def __init__(self, parents: dict[str, str]) -> None:
        self.parents = parents
        self.lookups = 0

    def __getitem__(self, key: str) -> str:
        self.lookups += 1
        return self.parents[key]

    def __contains__(self, key: object) -> bool:
        self.lookups += 1
        return key in self.parents

    def __iter__(self) -> Iterator[str]:
        return iter(self.parents)

    def __len__(self) -> int:
        return len(self.parents)


@pytest.fixture
def compositions(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """How many pose products are computed."""
    counter = {"n": 0}
    original = Pose.compose

    def counting(self: Pose, other: Pose) -> Pose:
        counter["n"] += 1
        return original(self, other)

    monkeypatch.setattr(Pose, "compose", counting)
    return counter


@pytest.fixture
def comparisons(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """How many names 'did you mean' compares (difflib sets one side per candidate)."""
    counter = {"n": 0}
    original = difflib.SequenceMatcher.set_seq1

    def counting(self: difflib.SequenceMatcher[str], a: Any) -> None:
        counter["n"] += 1
        original(self, a)

    monkeypatch.setattr(difflib.SequenceMatcher, "set_seq1", counting)
    return counter


class RecordingSchema:
    """Stands in for a compiled XSD and records what libxml2 is handed: elements and sibling lists."""

    def __init__(self, schema: etree.XMLSchema) -> None:
        self.schema = schema
        self.elements = 0
        self.longest_siblings = 0

    def validate(self, root: etree._Element) -> bool:
        for element in root.iter(etree.Element):
            self.elements += 1
            self.longest_siblings = max(self.longest_siblings, len(element))
        return bool(self.schema.validate(root))

    @property
    def error_log(self) -> Any:
        return self.schema.error_log


@pytest.fixture
def libxml2(monkeypatch: pytest.MonkeyPatch) -> dict[str, RecordingSchema]:
    recorded: dict[str, RecordingSchema] = {}
    original = structure.load_schema

    def recording(name: str) -> SchemaInfo:
        info = original(name)
        recorded[name] = recorded.get(name) or RecordingSchema(info.schema)
        return dataclasses.replace(info, schema=recorded[name])  # type: ignore[arg-type]

    monkeypatch.setattr(structure, "load_schema", recording)
    return recorded


def with_peak_memory(action: Callable[[], T]) -> tuple[T, int]:
    """What ``action`` returns, and the peak of Python's allocations while it ran (bytes)."""
    tracemalloc.start()
    try:
        return action(), tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def chain_cell(n: int, order: list[int]) -> str:
    """Frame i's parent is frame i-1: one chain n frames long, written in ``order``."""
    frames = "".join(f'<frame name="f{i}" parent="{f"f{i - 1}" if i else WORLD}" xyz="0.001 0 0"/>\n' for i in order)
    return f'<cell name="chain">\n{frames}</cell>\n'


# ------------------------------------------------------------------------------ frame chains
def test_a_5000_frame_parent_chain_validates_in_linear_work(tmp_path: Path, compositions: dict[str, int]) -> None:
    """Once cubic: 800 frames took 6 s, 5,000 did not finish in 120 s."""
    n = 5000
    path = tmp_path / "chain.xml"
    path.write_text(chain_cell(n, list(range(n - 1, -1, -1))))  # children first: the worst order for a naive walk
    found, peak = with_peak_memory(lambda: validate_cell(path))
    assert found == []
    assert compositions["n"] == n  # every world pose composed once, none again
    assert peak < 400 * path.stat().st_size  # about 30 MB here; a few hundred bytes per byte of input


@SETTINGS
@given(n=st.integers(2, 400), seed=st.integers(0, 2**16), cycle=st.booleans())
def test_ordering_a_frame_tree_looks_each_frame_up_once(n: int, seed: int, cycle: bool) -> None:
    rng = random.Random(seed)
    names = [f"f{i}" for i in range(n)]
    parents = {name: rng.choice(names[:i]) if i else WORLD for i, name in enumerate(names)}  # a tree below f0
    if cycle:
        parents[names[0]] = names[-1]  # f0 below the last frame, which is below f0: a cycle
    shuffled = dict(rng.sample(list(parents.items()), n))
    counting = CountingParents(shuffled)
    ordered = order_frames(counting)
    assert counting.lookups <= 2 * n
    placed = {WORLD}
    for name in ordered.order:  # parents first
        assert parents[name] in placed
        placed.add(name)
    assert bool(ordered.cycles) == cycle and set(ordered.order) | ordered.broken == set(names)


def test_a_cycle_in_a_long_chain_is_found_in_linear_work(tmp_path: Path) -> None:
    n = 5000
    parents = {f"f{i}": f"f{i - 1}" for i in range(1, n)}
    parents["f0"] = f"f{n - 1}"
    counting = CountingParents(parents)
    ordered = order_frames(counting)
    assert counting.lookups <= 2 * n
    assert len(ordered.cycles) == 1 and ordered.cycles[0][0] == "f1" and len(ordered.cycles[0]) == n  # named from the first written


# ------------------------------------------------------------------------------ unknown names
def wide_cell(n: int) -> str:
    return '<cell name="wide">\n' + "".join(f'<frame name="frame_{i}" xyz="0 0 0" kind="hole"/>\n' for i in range(n)) + "</cell>\n"


def unknown_frames_app(n: int) -> str:
    ops = "".join(
        f'<operation id="{i}"><left_arm><function name="debur_drilling"><params><param value="nope_{i}"/></params></function></left_arm></operation>\n'
        for i in range(n)
    )
    return f'<application name="a" robot="nextage" cell="cells/wide.xml">\n{ops}</application>\n'


def test_100000_unknown_frames_against_a_200000_frame_cell(tmp_path: Path, comparisons: dict[str, int], compositions: dict[str, int]) -> None:
    """Once two minutes of 'did you mean': now a bounded search for the first few, none for the rest."""
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "wide.xml").write_text(wide_cell(200_000))
    path = tmp_path / "app.xml"
    path.write_text(unknown_frames_app(100_000))
    found = validate_application(path, CATALOG)
    assert len(found) == MAX_DIAGNOSTICS + 1
    assert "wide.xml is too large to run: its model with 200,000 frames" in found[0].message  # refused, clearly
    assert found[1].message == "param 1 (hole) of debur_drilling: unknown frame 'nope_0' in the cell model"
    last = found[-1]
    assert isinstance(last, Omitted) and last.message.startswith("and 99,901 more problems (99,901 errors) not shown")
    assert count_problems(found) == (100_001, 0)  # every unknown frame counted
    assert comparisons["n"] <= validation.MAX_SUGGESTIONS * 4 * 48 + 100  # at most 100 questions of at most 192 names
    assert compositions["n"] < 40_000  # the snapshot was sized up to the message limit, not for all 200,000 frames


def test_a_suggestion_is_still_found_in_a_large_cell(tmp_path: Path, comparisons: dict[str, int]) -> None:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "wide.xml").write_text(wide_cell(20_000).replace('name="frame_777"', 'name="drill_777"'))
    text = unknown_frames_app(1).replace("nope_0", "dril_777")
    path = tmp_path / "app.xml"
    path.write_text(text)
    messages = [d.message for d in validate_application(path, CATALOG)]
    assert "param 1 (hole) of debur_drilling: unknown frame 'dril_777' in the cell model (did you mean 'drill_777'?)" in messages
    assert comparisons["n"] <= 4 * 48


@SETTINGS
@given(n=st.integers(1, 400))
def test_suggestions_stop_after_the_first_hundred(tmp_path: Path, n: int) -> None:
    (tmp_path / "cells").mkdir(exist_ok=True)
    (tmp_path / "cells" / "wide.xml").write_text(wide_cell(10))
    text = unknown_frames_app(n).replace("nope_", "frame_x")
    path = tmp_path / "app.xml"
    path.write_text(text)
    found = validate_application(path, CATALOG)
    hints = sum("did you mean" in d.message for d in found)
    assert hints == min(n, MAX_DIAGNOSTICS)  # every shown one has its hint (each is within the budget)
    assert count_problems(found)[0] == n


# ------------------------------------------------------------------------------ the structure check
@SETTINGS
@given(n=st.integers(50, 3000), nested=st.booleans())
def test_schema_work_is_linear_and_no_sibling_list_is_long(tmp_path: Path, libxml2: dict[str, RecordingSchema], n: int, nested: bool) -> None:
    """libxml2 names each error's path by counting its preceding siblings: n bad siblings cost n²/2.
    No document handed to it has more than a window of siblings."""
    libxml2.clear()
    frames = '<frame name="1"><actual xyz="a"/></frame>' * n
    body = f'<frame name="top">{frames}</frame>' if nested else frames
    path = tmp_path / "bad.xml"
    path.write_text(f'<cell name="c">{body}</cell>')
    found = validate_cell(path)
    recorded = libxml2["cell"]
    elements = 2 * n + 2
    assert recorded.longest_siblings <= structure.WINDOW + 1  # a window and the stand-in before it
    assert recorded.elements <= 6 * elements  # each window with its scaffold, a couple of passes
    assert count_problems(found)[0] >= 2 * n  # a bad name and a bad xyz each (and the names repeat)


def test_a_flood_of_unknown_elements_costs_one_pass(tmp_path: Path, libxml2: dict[str, RecordingSchema]) -> None:
    n = 200_000
    path = tmp_path / "flood.xml"
    path.write_text('<cell name="c">' + "<x/>" * n + "</cell>")
    found = validate_cell(path)
    assert found[0].message == "<x> is not allowed here inside <cell>; expected <frame>, <element>, <zone>, <joint_pose> or <robot>"
    assert count_problems(found) == (n, 0)
    assert libxml2["cell"].elements <= 3 * n


def test_more_elements_than_the_limit_are_refused_before_parsing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    parsed: list[int] = []
    original = etree.fromstring
    monkeypatch.setattr(safe_xml.etree, "fromstring", lambda *a, **k: parsed.append(1) or original(*a, **k))
    path = tmp_path / "flood.xml"
    head = '<cell name="c">\n'
    path.write_text(head + "<x/>" * MAX_ELEMENTS + "</cell>")  # the root and a million: one over
    found = [str(d) for d in validate_cell(path)]
    column = len("<x/>") * (MAX_ELEMENTS - 1) + 1
    assert found == [f"{path}:2:{column}: the file has more than {MAX_ELEMENTS:,} elements, the limit; split it "
                     "(a cell model or an application this large is a generated file gone wrong)"]
    assert parsed == []


def test_more_attributes_than_the_limit_are_refused_before_parsing(tmp_path: Path) -> None:
    path = tmp_path / "attributes.xml"
    path.write_text('<cell name="c"><frame name="f" ' + " ".join(f'a{i}=""' for i in range(MAX_ATTRIBUTES)) + "/></cell>")
    found = [d.message for d in validate_cell(path)]
    assert found == [f"the file has more than {MAX_ATTRIBUTES:,} attributes, the limit; split it "
                     "(a cell model or an application this large is a generated file gone wrong)"]


def test_comments_are_not_kept_and_memory_follows_the_bytes(tmp_path: Path) -> None:
    """31 MB of comments took 560 MB: each was a node of the tree."""
    path = tmp_path / "comments.xml"
    path.write_text('<cell name="c">' + "<!-- a comment -->\n" * 200_000 + '<frame name="f"/></cell>')
    doc, _ = read_xml(path)
    assert doc is not None and list(doc.root.iter(etree.Comment)) == []
    found, peak = with_peak_memory(lambda: validate_cell(path))
    assert found == []
    assert peak < 4 * path.stat().st_size  # the bytes, the text and the line table


# ------------------------------------------------------------------------------ the report
def test_the_report_stops_after_a_hundred_and_says_how_many_more(tmp_path: Path) -> None:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    ops = "".join(f'<operation id="{i}"><left_arm><function name="no_such_{i}"/></left_arm></operation>\n' for i in range(1000))
    path = tmp_path / "app.xml"
    path.write_text(f'<application name="a" robot="nextage" cell="cells/rivet_cell.xml">\n{ops}</application>\n')
    found = validate_application(path, CATALOG)
    assert len(found) == MAX_DIAGNOSTICS + 1 and found == sorted(found, key=lambda d: d.sort_key())
    assert [d.line for d in found[:MAX_DIAGNOSTICS]] == list(range(2, 2 + MAX_DIAGNOSTICS))  # the first ones, by position
    assert str(found[-1]) == (f"{path}:{1 + MAX_DIAGNOSTICS}:40: and 900 more problems (900 errors) not shown: "
                              f"the report stops after {MAX_DIAGNOSTICS}; fix these and validate again")
    assert count_problems(found) == (1000, 0)


def test_the_structure_check_leaves_the_tree_as_it_found_it(tmp_path: Path) -> None:
    text = '<cell name="c">' + "".join(f'<frame name="f{i}"><x/><actual/><frame name="g{i}"/>{"<y/>" * (i % 3)}</frame>' for i in range(300)) + "</cell>"
    path = tmp_path / "c.xml"
    path.write_text(text)
    doc, _ = read_xml(path)
    assert doc is not None
    before = etree.tostring(doc.root)
    assert structure.validate_structure(doc, "cell").has_errors
    assert etree.tostring(doc.root) == before


_PIECES = [
    '<frame name="z"/>', "<junk/>", "<junk><frame name='y'/></junk>", '<frame name="1"/>', "<actual/>", '<actual xyz="a"/>',
    '<element name="q"/>', '<frame name="n"><frame name="m"/><actual/><actual/></frame>', '<joint_pose name="j" joints="1 2"/>', "<joint_pose/>",
    "<param value='x'/>", "<left_arm><function name='wait'/></left_arm>", '<function name="wait"/>', "<description>d</description>",
    '<error_policy retries="x"/>', '<operation id="9"><arm><function name="wait"/></arm></operation>', "<operation id='8'/>",
    "<params><param/></params>", "<torso_head/>", "text",
]


@SETTINGS
@given(data=st.data(), cell=st.booleans())
def test_checking_in_windows_says_exactly_what_checking_whole_says(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, data: st.DataObject, cell: bool) -> None:
    """With windows of one element, every sibling list of a random mutant is split: same report."""
    text = CELL_XML if cell else APP_XML
    for _ in range(data.draw(st.integers(1, 6))):
        ends = [i for i, c in enumerate(text) if c == ">"][:-1]
        cut = data.draw(st.sampled_from(ends)) + 1
        text = text[:cut] + "".join(data.draw(st.lists(st.sampled_from(_PIECES), min_size=1, max_size=4))) + text[cut:]
    (tmp_path / "cells").mkdir(exist_ok=True)
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    path = tmp_path / "mutant.xml"
    path.write_text(text)

    def report() -> list[str]:
        return [str(d) for d in (validate_cell(path) if cell else validate_application(path, CATALOG))]

    monkeypatch.setattr(structure, "WINDOW", 10**9)
    whole = report()
    monkeypatch.setattr(structure, "WINDOW", 1)
    assert report() == whole


@SETTINGS
@given(cut=st.integers(0, 4000), junk=st.binary(max_size=30), window=st.sampled_from([1, 2, 64]))
def test_cut_or_garbled_large_files_give_diagnostics_never_exceptions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, cut: int, junk: bytes, window: int) -> None:
    """Sibling lists longer than a window, cut anywhere and garbled: only diagnostics come back."""
    monkeypatch.setattr(structure, "WINDOW", window)
    frames = "".join(f'<frame name="f{i}" xyz="0 {i % 5} 0"><frame name="g{i}"/><x/></frame>' for i in range(150))
    data = f'<cell name="c">{frames}<joint_pose name="p" joints="1 2"/></cell>'.encode()
    cut = min(cut, len(data))
    path = tmp_path / "garbled.xml"
    path.write_bytes(data[:cut] + junk + data[cut:])
    found = validate_cell(path)
    assert found == sorted(found, key=lambda d: d.sort_key())
    assert all(d.line >= 1 and d.col >= 1 and d.message for d in found)
