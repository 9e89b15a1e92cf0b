"""The studio's builder holds loops and calls as blocks (issue 24 item 4): what a user relies on, without a browser.

Opening a shipped looped application and saving it unchanged gives the same XML in canonical form
(C14N 2.0, comments kept, whitespace between elements set aside -- not byte for byte: the builder
writes through lxml, two spaces a level) and the same expanded operations; edits of loops, calls
and the operations inside them are checked, placed at their block or cell, saved and run.
"""
from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

from app_functions.registry import full_catalog  # noqa: E402
from execution_engine.app_model import load_application  # noqa: E402
from operator_station.blocks import BLOCK_KINDS, BlockDocument, BlockKind  # noqa: E402
from operator_station.blocks_xml import canonical, parse_blocks, read_blocks, write_blocks  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from test_studio_server import ROOT, client_for, station_args  # noqa: E402

CATALOG = full_catalog()
#: The shipped applications with loops or calls, as the builder opens them (relative to apps_xml).
LOOPED = ["rivet_loop.xml", "rivet_blocks.xml", "examples/pallet_grid.xml", "rivet_loop_branch.xml"]


@pytest.fixture
def apps(tmp_path: Path) -> Path:
    """A copy of apps_xml: the looped applications, their library block and their cell."""
    for folder in ("cells", "blocks", "examples"):
        shutil.copytree(ROOT / "apps_xml" / folder, tmp_path / folder)
    for name in ("rivet_loop.xml", "rivet_blocks.xml", "rivet_installation.xml", "rivet_loop_branch.xml"):
        shutil.copy(ROOT / "apps_xml" / name, tmp_path / name)
    return tmp_path


def expanded(path: Path) -> list[tuple[str, str | None, str, list[tuple[str, str, tuple[str, ...]]]]]:
    """What a file runs: each operation with its iteration and its calls (a call's iteration names the line
    of the call, which the builder's layout moves: set aside)."""
    app = load_application(path, CATALOG)
    return [(op.id, op.name, re.sub(r" at \S+:\d+", "", op.origin), [(g, c.function, tuple(c.params)) for g, c in op.calls.items()])
            for op in app.operations]


def post(client: Any, route: str, path: str, document: dict[str, Any]) -> Any:
    return client.post(f"/api/{route}", json={"path": path, "document": document})


@pytest.mark.parametrize("name", LOOPED)
def test_a_shipped_looped_application_opens_as_blocks_and_saves_back_canonically_equal_and_expanding_the_same(apps: Path, name: str) -> None:
    client = client_for(build_station(station_args(), CATALOG, apps))
    before_bytes, before_ops = (apps / name).read_bytes(), expanded(apps / name)
    opened = client.post("/api/open", json={"path": name}).json()
    assert opened["ok"] and "operations" not in opened["document"] and opened["document"]["unheld"] == []
    kinds = [step["type"] for step in opened["document"]["body"]]
    assert kinds[0] == "operation" and kinds[-1] == "operation" and "for_each" in kinds
    saved = post(client, "save", name, opened["document"]).json()
    assert saved["ok"], saved
    assert canonical((apps / name).read_bytes()) == canonical(before_bytes)
    assert expanded(apps / name) == before_ops
    again = client.post("/api/open", json={"path": name}).json()["document"]
    assert again == opened["document"]  # saving what was saved changes nothing
    assert post(client, "save", name, again).json()["ok"] and (apps / name).read_bytes() == (apps / name).read_bytes()


def test_the_branch_demonstrator_opens_with_its_if_and_else_as_blocks_and_saves_its_branches_back(apps: Path) -> None:
    """if and else are kinds of block: the page gets their attributes and bodies, and a save keeps every
    operation under the same conditions (an edit of the if's outcome is one more condition changed, no more)."""
    client = client_for(build_station(station_args(), CATALOG, apps))
    name = "rivet_loop_branch.xml"
    before = [(op.id, op.when) for op in load_application(apps / name, CATALOG).operations]
    document = client.post("/api/open", json={"path": name}).json()["document"]
    loop = document["body"][1]
    assert [step["type"] for step in loop["body"]] == ["operation", "operation", "if", "else"]
    branch, otherwise = loop["body"][2], loop["body"][3]
    assert branch["attributes"] == {"group": "left_arm", "operation": "look_{hole}", "outcome": "found"} and otherwise["attributes"] == {}
    assert [op["id"] for op in branch["body"]] == ["debur_{hole}", "insert_{hole}"] and [op["id"] for op in otherwise["body"]] == ["put_back_{hole}"]
    assert post(client, "save", name, document).json()["ok"]
    assert [(op.id, op.when) for op in load_application(apps / name, CATALOG).operations] == before
    branch["attributes"]["outcome"] = "not_found"
    assert post(client, "save", name, document).json()["ok"]
    after = dict((op.id, op.when) for op in load_application(apps / name, CATALOG).operations)
    assert [c.outcome for c in after["debur_drill_2"]] == ["not_found"] and [c.holds for c in after["put_back_drill_2"]] == [False]
    branch["attributes"]["outcome"] = "in_range"
    answer = post(client, "validate", name, document).json()
    errors = [m for m in answer["messages"] if m["severity"] == "error"]
    assert len(errors) == 1 and errors[0]["step"] == [1, 2] and "which locate does not have: its outcomes: found, not_found" in errors[0]["message"]


def test_the_library_block_reads_and_writes_back_canonically_equal() -> None:
    """apps_xml/blocks/rivet_block.xml is valid only through its caller: its round trip is the model's own."""
    path = ROOT / "apps_xml" / "blocks" / "rivet_block.xml"
    document, problems = read_blocks(path)
    assert document is not None and not problems
    text, lines = write_blocks(document)
    assert canonical(text.encode("utf-8")) == canonical(path.read_bytes()) and len(lines) == text.count("\n") + 1
    assert parse_blocks(text.encode("utf-8"), path)[0] == document


def test_loop_call_and_body_edits_are_saved_and_run_with_their_iterations(apps: Path) -> None:
    station = build_station(station_args(), CATALOG, apps)
    client = client_for(station)
    document = client.post("/api/open", json={"path": "rivet_blocks.xml"}).json()["document"]
    loop = document["body"][1]
    assert loop["type"] == "for_each" and loop["attributes"] == {"var": "hole", "in": "kind:hole"}
    assert loop["body"][0]["type"] == "call" and loop["body"][0]["params"] == [{"name": "hole", "value": "{hole}"}, {"name": "slot", "value": "rivet_{index}"}]
    loop["attributes"]["in"] = "drill_3 drill_1"  # a list instead of the kind
    repeat = {"type": "repeat", "attributes": {"count": "2", "var": "n"}, "params": [], "comments": [], "trailer": [], "body": [
        {"type": "operation", "id": "look_{n}", "name": "look {n}", "comments": [],
         "calls": [{"group": "torso_head", "function": "move_to_joint_pose", "params": [{"value": "look_at_part", "name": None}]}]}]}
    document["body"].insert(2, repeat)  # a new block after the loop
    answer = post(client, "validate", "edited.xml", document).json()
    assert answer["ok"], answer["messages"]
    assert post(client, "save", "edited.xml", document).json()["ok"]
    ops = expanded(apps / "edited.xml")
    assert [(op_id, origin) for op_id, _, origin, _ in ops] == [
        ("prepare", ""),
        ("debur_drill_3", "for_each hole=drill_3 > call blocks/rivet_block.xml hole=drill_3 slot=rivet_1"),
        ("insert_drill_3", "for_each hole=drill_3 > call blocks/rivet_block.xml hole=drill_3 slot=rivet_1"),
        ("debur_drill_1", "for_each hole=drill_1 > call blocks/rivet_block.xml hole=drill_1 slot=rivet_2"),
        ("insert_drill_1", "for_each hole=drill_1 > call blocks/rivet_block.xml hole=drill_1 slot=rivet_2"),
        ("look_1", "repeat n=1"), ("look_2", "repeat n=2"), ("home", ""),
    ]
    assert client.post("/api/open", json={"path": "edited.xml"}).json()["document"]["body"][2] == repeat
    # Start runs the edited file, loops expanded; the page's records and operation list carry each iteration
    run = post(client, "run", "edited.xml", document).json()
    assert run["ok"], run
    assert station.session is not None
    station.session.join(120.0)
    assert station.feed.snapshot.status["state"] == "finished"
    assert [o["iteration"] for o in station.feed.snapshot.operations][5:7] == ["repeat n=1", "repeat n=2"]
    _, records, _, _ = station.feed.read(0, 0)
    starts = {(r["operation"], r.get("iteration", "")) for r in records if r["event"] == "function_start"}
    assert ("look_2", "repeat n=2") in starts and ("prepare", "") in starts
    timeline = client.get("/api/timeline").json()
    assert {op["id"]: op["iteration"] for op in timeline["operations"]}["look_1"] == "repeat n=1"


def test_a_message_inside_a_loop_is_placed_at_its_cell_and_one_of_a_loop_at_its_block(apps: Path) -> None:
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = client.post("/api/open", json={"path": "rivet_loop.xml"}).json()["document"]
    document["body"][1]["body"][0]["calls"][0]["params"][0]["value"] = "{hole}_x"  # debur_drilling of a frame that is not there
    document["body"].insert(2, {"type": "for_each", "attributes": {"var": "p", "in": "grid:rivet_1 2xx 0.03 0.03"}, "body": [
        {"type": "operation", "id": "pick_{p}", "name": None, "comments": [], "calls": []}]})
    answer = post(client, "validate", "rivet_loop.xml", document).json()
    assert not answer["ok"]
    placed: dict[tuple[Any, ...], list[str]] = {}
    for m in answer["messages"]:
        placed.setdefault((tuple(m["step"] or ()), m["group"], m["param"]), []).append(m["message"])
    inside = placed[((1, 0), "left_arm", 0)]  # one message per iteration, each naming it, all at the cell written once
    assert [f"'drill_{i}_x'" in m and f"(in for_each hole=drill_{i})" in m for i, m in enumerate(inside, start=1)] == [True] * 4
    assert "grid:rivet_1 2xx" in placed[((2,), None, None)][0]
    assert post(client, "run", "rivet_loop.xml", document).json()["ok"] is False
    assert not post(client, "save", "rivet_loop.xml", document).json()["ok"]
    assert (apps / "rivet_loop.xml").read_bytes() == (ROOT / "apps_xml" / "rivet_loop.xml").read_bytes()


def test_a_flat_file_with_flags_sync_keeps_it(apps: Path) -> None:
    text = (apps / "rivet_installation.xml").read_text(encoding="utf-8").replace('cell="cells/rivet_cell.xml"', 'cell="cells/rivet_cell.xml" sync="flags"', 1)
    (apps / "flags.xml").write_text(text, encoding="utf-8")
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = client.post("/api/open", json={"path": "flags.xml"}).json()["document"]
    assert document["sync"] == "flags"
    assert post(client, "save", "flags.xml", document).json()["ok"]
    assert load_application(apps / "flags.xml", CATALOG).sync == "flags"


def test_what_the_builder_does_not_hold_is_never_written_over_and_an_unchanged_file_is_checked_as_itself(apps: Path) -> None:
    text = (apps / "rivet_loop.xml").read_text(encoding="utf-8").replace('<params><param value="rivet_{index}"/>',
                                                                        '<params><!-- the slot of the same place --><param value="rivet_{index}"/>', 1)
    (apps / "noted.xml").write_bytes(text.encode("utf-8"))
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = client.post("/api/open", json={"path": "noted.xml"}).json()["document"]
    assert document["unheld"] == ["a comment inside <params> at line 22"]
    unchanged = post(client, "validate", "noted.xml", document).json()
    assert unchanged["ok"], unchanged  # the file itself, loops and comment
    saved = post(client, "save", "noted.xml", document).json()
    assert not saved["ok"] and saved["messages"][-1]["message"].endswith(
        "holds a comment inside <params> at line 22, which the builder does not hold: saving would drop them; edit the file as text, or save under another name")
    document["body"][0]["name"] = "edited"
    refused = post(client, "validate", "noted.xml", document).json()
    assert not refused["ok"] and "an edit cannot be checked, run or saved without them" in refused["messages"][0]["message"]
    assert post(client, "run", "noted.xml", document).json()["ok"] is False
    assert (apps / "noted.xml").read_bytes() == text.encode("utf-8")


def test_comments_inside_an_operation_are_kept_where_they_were_written(apps: Path) -> None:
    """The bin-transfer example explains a move inside its operation: an edit elsewhere keeps the comment above that call."""
    shutil.copy(ROOT / "apps_xml" / "examples" / "bin_transfer.xml", apps / "examples" / "bin_transfer.xml")
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = client.post("/api/open", json={"path": "examples/bin_transfer.xml"}).json()["document"]
    assert document["unheld"] == [] and document["body"][6]["inner"] == {"right_arm": [" tool z points out of the hand (down here): -60 mm in tool z lifts the part "]}
    document["body"][0]["name"] = "edited"
    assert post(client, "save", "examples/bin_transfer.xml", document).json()["ok"]
    written = (apps / "examples" / "bin_transfer.xml").read_text(encoding="utf-8")
    assert '<operation id="7" name="lift part 1">\n    <!-- tool z points out of the hand (down here): -60 mm in tool z lifts the part -->\n    <right_arm>' in written
    assert client.post("/api/open", json={"path": "examples/bin_transfer.xml"}).json()["document"] == document
    original = expanded(ROOT / "apps_xml" / "examples" / "bin_transfer.xml")
    assert expanded(apps / "examples" / "bin_transfer.xml") == [(original[0][0], "edited", *original[0][2:]), *original[1:]]


def step(**changes: Any) -> dict[str, Any]:
    return {"type": "for_each", "attributes": {"var": "h", "in": "drill_1"}, "body": [], **changes}


@pytest.mark.parametrize(("body", "error"), [
    ("no", "body: a list of steps is needed"),
    ([{"type": "while"}], "step 1: type must be operation or one of for_each, repeat, call, if, else"),
    ([{"type": "if", "attributes": {"group": "left_arm", "operation": "look"}, "body": []}], "step 1: <if> needs outcome"),
    ([step(attributes={"var": "h", "in": "a", "onload": "x"})], "step 1: <for_each> takes the attributes var, in, index, with text values"),
    ([step(attributes={"var": "h"})], "step 1: <for_each> needs in"),
    ([{"type": "call", "attributes": {"application": "b.xml"}, "body": [step()]}], "step 1: <call> has no body"),
    ([{"type": "call", "attributes": {"application": "b.xml"}, "params": [{"name": 3, "value": "x"}]}], "step 1: each param of a call needs a text name and value"),
    ([step(body=[step(body=[{"type": "operation", "id": 7, "calls": []}])])], "step 1.1.1: id must be text"),
    ([step(body=[{"type": "operation", "id": "a", "calls": [{"group": "left arm", "function": "wait", "params": []}]}])], "step 1.1: group 'left arm' is not a name"),
    ([step(attributes={"var": "h", "in": "drill\x01"})], "step 1: in holds a character XML cannot carry"),
])
def test_a_hostile_body_is_one_line_and_changes_nothing(apps: Path, body: Any, error: str) -> None:
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = {"name": "a", "robot": "nextage", "cell": "cells/rivet_cell.xml", "body": body}
    for route in ("validate", "save", "run"):
        answer = post(client, route, "rivet_loop.xml", document)
        assert answer.status_code == 400 and answer.json()["error"] == error and "\n" not in error
    assert (apps / "rivet_loop.xml").read_bytes() == (ROOT / "apps_xml" / "rivet_loop.xml").read_bytes()


def test_nesting_and_size_are_bounded_before_anything_is_built() -> None:
    deep: dict[str, Any] = {"type": "operation", "id": "x", "calls": []}
    for _ in range(40):
        deep = step(body=[deep])
    with pytest.raises(ValueError, match="blocks nested more than 16 deep"):
        BlockDocument.from_json({"name": "a", "robot": "nextage", "body": [deep]})
    many = [{"type": "operation", "id": str(i), "calls": []} for i in range(100_001)]
    with pytest.raises(ValueError, match="more than 100,000 steps"):
        BlockDocument.from_json({"name": "a", "robot": "nextage", "body": many})


def test_a_branch_is_one_more_kind_of_block(monkeypatch: pytest.MonkeyPatch) -> None:
    """Declared as kinds (their attributes, a body each), the builder's model reads, takes from the page and writes
    branches with no other change -- the else inside its if or beside it (the model holds what is written; the
    validator says where an else may stand)."""
    monkeypatch.setitem(BLOCK_KINDS, "if", BlockKind("if", ("operation", "group", "outcome"), ("operation", "outcome")))
    monkeypatch.setitem(BLOCK_KINDS, "else", BlockKind("else", (), ()))
    text = (ROOT / "apps_xml" / "rivet_loop.xml").read_bytes().replace(b"""    <operation id="insert_{hole}" name="insert {index}">""", b"""    <if operation="debur_{hole}" group="left_arm" outcome="found">
      <else><!-- not found: the rivet goes back --></else>
    </if>
    <else/>
    <operation id="insert_{hole}" name="insert {index}">""")
    document, _ = parse_blocks(text, "branch.xml")
    assert document is not None and document.unheld == []
    branch = document.body[1].body[1]
    assert (branch.kind, branch.attributes, branch.body[0].kind, branch.body[0].trailer) == (
        "if", {"operation": "debur_{hole}", "group": "left_arm", "outcome": "found"}, "else", [" not found: the rivet goes back "])
    assert BlockDocument.from_json(document.to_json()) == document
    written, _ = write_blocks(document)
    assert canonical(written.encode("utf-8")) == canonical(text)


def test_an_operation_moved_into_a_loop_is_checked_there(apps: Path) -> None:
    """Moved into the loop (⇥ in the page), `home` would come out once per hole with the same id: refused at its cell."""
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = client.post("/api/open", json={"path": "rivet_loop.xml"}).json()["document"]
    home = document["body"].pop()
    document["body"][1]["body"].append(home)
    answer = post(client, "validate", "rivet_loop.xml", document).json()
    assert not answer["ok"]
    errors = [m for m in answer["messages"] if m["severity"] == "error"]
    assert [(m["step"], m["operation"]) for m in errors] == [([1, 2], 3)] and "operation id 'home' comes out the same" in errors[0]["message"]
    home["id"] = "home_{hole}"
    assert post(client, "save", "rivet_loop.xml", document).json()["ok"]
    assert [op_id for op_id, *_ in expanded(apps / "rivet_loop.xml")][-3:] == ["debur_drill_4", "insert_drill_4", "home_drill_4"]


def test_a_call_reads_only_files_in_the_station_folders(apps: Path, tmp_path_factory: pytest.TempPathFactory) -> None:
    """Validating a call reads the called file: the page may name only files it could open."""
    outside = tmp_path_factory.mktemp("outside") / "secret.xml"
    outside.write_text("<config/>", encoding="utf-8")
    client = client_for(build_station(station_args(), CATALOG, apps))
    document = client.post("/api/open", json={"path": "rivet_blocks.xml"}).json()["document"]
    document["body"][1]["body"][0]["attributes"]["application"] = str(outside)
    for route in ("validate", "save", "run"):
        answer = post(client, route, "rivet_blocks.xml", document)
        assert answer.status_code == 400 and answer.json()["error"].startswith(f"step 2.1: call of {outside}: outside the station's folders")
    assert (apps / "rivet_blocks.xml").read_bytes() == (ROOT / "apps_xml" / "rivet_blocks.xml").read_bytes()
