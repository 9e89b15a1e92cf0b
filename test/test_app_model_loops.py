"""Loops and calls in the application XML (issue 24 items 1 and 3): expanded at load time, every
problem refused before anything moves at the line inside the loop, naming the iteration."""
from __future__ import annotations

from pathlib import Path

import pytest
from app_model_support import at, pos

from app_functions.registry import full_catalog
from execution_engine.app_model import ApplicationError, load_application, validate_application
from execution_engine.app_model.document import read_document
from execution_engine.app_model.expand import MAX_DEPTH, MAX_OPERATIONS
from operator_station.builder import save_document, validate

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
CATALOG = full_catalog()


def app(body: str, cell: Path | None = CELL) -> str:
    cell_attr = f' cell="{cell}"' if cell is not None else ""
    return f'<?xml version="1.0"?>\n<application name="t" robot="nextage"{cell_attr}>\n{body}</application>\n'


def op(op_id: str, group: str, function: str, *params: str) -> str:
    inner = "".join(f'<param value="{p}"/>' for p in params)
    return f'  <operation id="{op_id}">\n    <{group}><function name="{function}"><params>{inner}</params></function></{group}>\n  </operation>\n'


def write(tmp_path: Path, text: str, name: str = "app.xml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def errors(path: Path) -> list[str]:
    return [str(d) for d in validate_application(path, CATALOG)]


def test_the_looped_demonstrator_expands_to_the_flat_one() -> None:
    flat = load_application(ROOT / "apps_xml" / "rivet_installation.xml", CATALOG)
    looped = load_application(ROOT / "apps_xml" / "rivet_loop.xml", CATALOG)
    called = load_application(ROOT / "apps_xml" / "rivet_blocks.xml", CATALOG)
    for other in (looped, called):
        assert [{g: (c.function, c.params) for g, c in o.calls.items()} for o in other.operations] == \
               [{g: (c.function, c.params) for g, c in o.calls.items()} for o in flat.operations]
    assert [o.id for o in looped.operations] == ["prepare"] + [f"{step}_drill_{i}" for i in range(1, 5) for step in ("debur", "insert")] + ["home"]
    text = (ROOT / "apps_xml" / "rivet_loop.xml").read_text()
    third = looped.operations[5]
    assert (third.id, third.origin, third.line) == ("debur_drill_3", "for_each hole=drill_3", pos(text, '<operation id="debur_{hole}"')[0])
    assert third.calls["left_arm"].line == pos(text, "debur_drilling")[0]
    assert looped.operations[0].origin == "" and looped.iterations()["insert_drill_4"] == "for_each hole=drill_4"
    block = ROOT / "apps_xml" / "blocks" / "rivet_block.xml"
    assert called.operations[3].calls["right_arm"].file == str(block) and called.operations[3].origin.startswith("for_each hole=drill_2 > call blocks/rivet_block.xml hole=drill_2 slot=rivet_2 at ")
    assert called.includes == (block.resolve(),)


def test_an_unknown_frame_in_the_list_is_refused_at_the_body_line_naming_the_iteration(tmp_path: Path) -> None:
    body = '  <for_each var="hole" in="drill_1 drill_7 drill_3">\n' + op("debur_{hole}", "left_arm", "debur_drilling", "{hole}") + "  </for_each>\n"
    text = app(body)
    path = write(tmp_path, text)
    assert errors(path) == [at(path, text, 'value="{hole}"', (
        "param 1 (hole) of debur_drilling: unknown frame 'drill_7' in the cell model (did you mean 'drill_4'?) (in for_each hole=drill_7)"
    ))]


def test_a_bad_constant_param_in_a_loop_is_one_line_naming_every_iteration(tmp_path: Path) -> None:
    body = '  <repeat count="3">\n' + op("s{index}", "left_arm", "set_speed", "7") + "  </repeat>\n"
    text = app(body)
    path = write(tmp_path, text)
    found = errors(path)
    assert len(found) == 1
    assert found[0].startswith(at(path, text, 'value="7"', "param 1 (fraction) of set_speed: "))
    assert found[0].endswith("(in repeat index=1; repeat index=2; repeat index=3)")


def test_substitution_reaches_ids_names_params_and_inner_lists(tmp_path: Path) -> None:
    body = ('  <for_each var="side" in="a, b">\n    <repeat count="2" var="n">\n'
            '      <for_each var="hole" in="drill_{n}">\n'
            '  <operation id="{side}_{n}_{hole}" name="{side} {index} {{x}}">\n'
            '    <left_arm><function name="wait_flag"><params><param value="f_{side}_{n}"/></params></function></left_arm>\n'
            '    <right_arm><function name="set_flag"><params><param value="f_{side}_{n}"/></params></function></right_arm>\n'
            '  </operation>\n      </for_each>\n    </repeat>\n  </for_each>\n')
    application = load_application(write(tmp_path, app(body)), CATALOG)
    assert [(o.id, o.name, o.calls["left_arm"].params[0]) for o in application.operations] == [
        ("a_1_drill_1", "a 1 {x}", "f_a_1"), ("a_2_drill_2", "a 1 {x}", "f_a_2"),
        ("b_1_drill_1", "b 1 {x}", "f_b_1"), ("b_2_drill_2", "b 1 {x}", "f_b_2"),
    ]
    assert application.operations[3].origin == "for_each side=b > repeat n=2 > for_each hole=drill_2"


def test_unknown_variables_are_refused_at_their_line(tmp_path: Path) -> None:
    text = app('  <for_each var="hole" in="drill_1">\n' + op("d_{hole}", "left_arm", "debur_drilling", "{hol}") + "  </for_each>\n"
               + op("x_{hole}", "left_arm", "gripper_open"))
    path = write(tmp_path, text)
    assert errors(path) == [
        at(path, text, 'value="{hol}"', "unknown variable {hol} in param 1 of debur_drilling '{hol}': the variables here: hole, index (in for_each hole=drill_1)"),
        at(path, text, 'id="x_{hole}"', "unknown variable {hole} in operation id 'x_{hole}': no loop or call around it defines any "
           "(a library block is checked through the application that calls it)"),
    ]


def test_an_id_that_is_the_same_in_two_iterations_is_refused_naming_both(tmp_path: Path) -> None:
    text = app('  <for_each var="hole" in="drill_1 drill_2">\n' + op("debur", "left_arm", "debur_drilling", "{hole}") + "  </for_each>\n")
    path = write(tmp_path, text)
    line = pos(text, '<operation id="debur"')[0]
    assert errors(path) == [at(path, text, 'id="debur"', (
        f"operation id 'debur' comes out the same in for_each hole=drill_1 ({path}:{line}) and in for_each hole=drill_2: "
        'put a loop variable in the id (id="insert_{hole}") so every iteration has its own'
    ))]


def test_kind_takes_the_cells_frames_in_order_and_refuses_a_kind_without_frames(tmp_path: Path) -> None:
    good = load_application(write(tmp_path, app('  <for_each var="s" in="kind:rivet_slot">\n' + op("p_{s}", "right_arm", "gripper_open") + "  </for_each>\n")), CATALOG)
    assert [o.id for o in good.operations] == ["p_rivet_1", "p_rivet_2", "p_rivet_3", "p_rivet_4", "p_rivet_5"]
    text = app('  <for_each var="s" in="kind:holes">\n' + op("p_{s}", "right_arm", "gripper_open") + "  </for_each>\n")
    path = write(tmp_path, text, "bad.xml")
    assert errors(path) == [at(path, text, 'in="kind', "in=\"kind:holes\": the cell has no frame of kind 'holes' (its kinds: fixture, hole, rivet_slot, tray)")]


def test_a_grid_makes_frames_under_its_origin(tmp_path: Path) -> None:
    application = load_application(ROOT / "apps_xml" / "examples" / "pallet_grid.xml", CATALOG)
    cell = application.cell
    assert cell is not None
    pockets = [o.calls["right_arm"].params[0] for o in application.operations if o.id.startswith("pick_")]
    assert pockets == ["rivet_1_1_1", "rivet_1_1_2", "rivet_1_2_1", "rivet_1_2_2"]
    for pocket, slot in zip(pockets, ("rivet_1", "rivet_2", "rivet_3", "rivet_4")):
        made, written = cell.pose(pocket), cell.pose(slot)
        assert (made.x, made.y, made.z) == pytest.approx((written.x, written.y, written.z), abs=1e-9)
        assert cell.frame(pocket).parent == "rivet_1" and cell.frame(pocket).kind == "rivet_slot"
        assert cell.frame(pocket).attributes["element"] == "ref_R10" and "box" not in cell.frame(pocket).attributes


@pytest.mark.parametrize(("spec", "words"), [
    ("rivet_1 2y2 0.03 0.03", "grid size '2y2' is not ROWSxCOLUMNS (whole numbers, e.g. 3x4)"),
    ("rivet_1 2x2 0.03", "grid needs 4 fields, got 3: grid:ORIGIN ROWSxCOLUMNS ROW_PITCH COLUMN_PITCH, e.g. grid:tray_origin 3x4 0.020 0.025"),
    ("rivet_1 2x2 3inch 0.03", "grid row pitch '3inch' is not a length (metres, or a number with m, cm or mm)"),
    ("rivet_1 2x2 0.03 1e308", "grid column pitch = 1e+308 m is outside ±100 m, the bound of a length in a cell"),
    ("rivet_1 1x2 0.03 0", "grid column pitch is 0: the 2 columns would be one place"),
    ("tray_9 2x2 0.03 0.03", "grid origin 'tray_9' is not a frame of the cell"),
    ("rivet_1 200x200 0.001 0.001", "grid size '200x200' makes 40,000 frames, more than the limit of 10,000"),
])
def test_a_malformed_grid_is_refused_naming_the_field(tmp_path: Path, spec: str, words: str) -> None:
    text = app(f'  <for_each var="s" in="grid:{spec}">\n' + op("p_{s}", "right_arm", "gripper_open") + "  </for_each>\n")
    path = write(tmp_path, text)
    assert errors(path) == [at(path, text, 'in="grid', f'in="grid:{spec}": {words}')]


def test_expansions_past_the_limits_are_refused_at_the_loops_line(tmp_path: Path) -> None:
    text = app('  <repeat count="1000">\n  <repeat count="1000" var="j">\n' + op("o{index}_{j}", "left_arm", "gripper_open") + "  </repeat>\n  </repeat>\n")
    path = write(tmp_path, text)
    assert errors(path) == [at(path, text, '<repeat count="1000">', (
        f"<repeat> expands to 1,000,000 operations (1,000 iterations), which takes the application past the limit of {MAX_OPERATIONS:,} operations"
    ))]
    names = [f"v{i}" for i in range(MAX_DEPTH + 1)]
    nested = "".join(f'<repeat count="1" var="{n}">\n' for n in names) + op("deep", "left_arm", "gripper_open") + "</repeat>\n" * len(names)
    text = app(nested)
    path = write(tmp_path, text, "deep.xml")
    assert errors(path) == [at(path, text, f'<repeat count="1" var="{names[-1]}">', f"<repeat> is nested {MAX_DEPTH + 1} deep in loops and calls, more than the limit of {MAX_DEPTH}")]


def test_an_inner_loop_may_not_take_a_variable_named_outside(tmp_path: Path) -> None:
    text = app('  <for_each var="hole" in="drill_1">\n  <for_each var="hole" in="drill_2">\n' + op("d_{hole}", "left_arm", "gripper_open") + "  </for_each>\n  </for_each>\n")
    path = write(tmp_path, text)
    assert errors(path) == [at(path, text, 'var="hole" in="drill_2"', "variable {hole} is already the variable of the loop at line 3: give this one another name")]


def block(hole_param: str = "{hole}", robot: str = "nextage", extra: str = "") -> str:
    return (f'<?xml version="1.0"?>\n<application name="blk" robot="{robot}">\n{extra}'
            + op("d_{hole}", "left_arm", "debur_drilling", hole_param) + "</application>\n")


def test_a_call_binds_its_params_and_its_errors_are_at_its_own_lines(tmp_path: Path) -> None:
    (tmp_path / "lib").mkdir()
    lib = tmp_path / "lib" / "blk.xml"
    lib.write_text(block())
    call = '  <call application="lib/blk.xml"><param name="hole" value="drill_{index}"/></call>\n'
    loaded = load_application(write(tmp_path, app('  <repeat count="2">\n' + call + "  </repeat>\n")), CATALOG)
    assert [o.calls["left_arm"].params[0] for o in loaded.operations] == ["drill_1", "drill_2"]
    bad = block("{hole}_x")
    lib.write_text(bad)
    text = app(call.replace("drill_{index}", "drill_3"))
    path = write(tmp_path, text, "caller.xml")
    line, col = pos(text, "<call")
    assert errors(path) == [at(lib, bad, 'value="{hole}_x"', (
        f"param 1 (hole) of debur_drilling: unknown frame 'drill_3_x' in the cell model (did you mean 'drill_3'?) "
        f"(in call lib/blk.xml hole=drill_3 at {path}:{line})"
    ))]
    broken = block().replace("<function ", "<functon ", 1)
    lib.write_text(broken)
    found = errors(path)
    assert at(path, text, 'application="', "called application lib/blk.xml has errors (listed with its name)") in found
    in_block = [f for f in found if f.startswith(str(lib))]
    assert len(in_block) == 1 and in_block[0].startswith(f"{lib}:4:")
    assert in_block[0].endswith(f": closing tag </function> does not match <functon> opened on line 4 (in called from {path}:{line}:{col})")


def test_call_cycles_other_robots_and_missing_files_are_refused(tmp_path: Path) -> None:
    (tmp_path / "a.xml").write_text(app('  <call application="b.xml"/>\n'))
    (tmp_path / "b.xml").write_text(app('  <call application="a.xml"/>\n'))
    assert errors(tmp_path / "a.xml") == [at(tmp_path / "b.xml", (tmp_path / "b.xml").read_text(), 'application="a.xml"', (
        "call cycle: a.xml -> b.xml -> a.xml; an application cannot call itself, directly or through others"
    ))]
    (tmp_path / "viper.xml").write_text(block(robot="viper").replace("left_arm", "arm"))
    text = app('  <call application="viper.xml"><param name="hole" value="drill_1"/></call>\n  <call application="none.xml"/>\n')
    path = write(tmp_path, text, "c.xml")
    assert errors(path) == [
        at(path, text, 'application="viper.xml"', "called application viper.xml is for adept_viper_s850, this one for nextage_open"),
        at(path, text, 'application="none.xml"', f"called application none.xml not found (looked for {tmp_path / 'none.xml'})"),
    ]


def test_a_variable_in_a_file_without_loops_is_refused(tmp_path: Path) -> None:
    text = app(op("1", "left_arm", "debur_drilling", "{hole}"))
    path = write(tmp_path, text)
    with pytest.raises(ApplicationError) as refused:
        load_application(path, CATALOG)
    assert str(refused.value.diagnostics[0]).startswith(at(path, text, 'value="{hole}"', "unknown variable {hole} in param 1 of debur_drilling"))


def test_the_builder_does_not_save_over_loops_it_cannot_show(tmp_path: Path) -> None:
    path = tmp_path / "loop.xml"
    path.write_text((ROOT / "apps_xml" / "rivet_loop.xml").read_text().replace('cell="cells/rivet_cell.xml"', f'cell="{CELL}"'))
    document, _ = read_document(path)
    assert document is not None and document.steps == ["<for_each> at line 18"] and [o.id for o in document.operations] == ["prepare", "home"]
    before = path.read_bytes()
    saved, messages = save_document(document, path, CATALOG)
    assert not saved and path.read_bytes() == before
    assert messages[-1].message == f"{path} holds <for_each> at line 18, which the builder does not show: saving would drop them; edit the file as text, or save under another name"
    checked, _, _ = validate(document, path, CATALOG)  # what the studio's Start runs: the file, loops and all
    assert checked is not None and len(checked.operations) == 10 and checked.operations[5].origin == "for_each hole=drill_3"
    document.operations[0].name = "edited"
    checked, refused, _ = validate(document, path, CATALOG)
    assert checked is None and [m.message for m in refused] == [
        f"{path} holds <for_each> at line 18, which the builder does not show: an edit of the rest cannot be checked, run or saved with them; edit the file as text"
    ]


@pytest.mark.parametrize("sync", ["operation", "flags"])
def test_loops_in_both_sync_modes_and_a_wait_no_iteration_can_end(tmp_path: Path, sync: str) -> None:
    def flags(values: str, extra: str = "") -> str:
        return (f'  <for_each var="v" in="a b">\n    <operation id="set_{{v}}"><left_arm><function name="set_flag"><params><param value="done_{{v}}"/>'
                '</params></function></left_arm></operation>\n  </for_each>\n'
                f'  <for_each var="v" in="{values}">\n    <operation id="wait_{{v}}"><right_arm><function name="wait_flag"><params>'
                '<param value="done_{v}"/></params></function></right_arm></operation>\n  </for_each>\n')

    good = app(flags("b a")).replace('robot="nextage"', f'robot="nextage" sync="{sync}"')
    loaded = load_application(write(tmp_path, good), CATALOG)
    assert loaded.sync == sync and [o.id for o in loaded.operations] == ["set_a", "set_b", "wait_b", "wait_a"]
    text = app(flags("a b c")).replace('robot="nextage"', f'robot="nextage" sync="{sync}"')
    path = write(tmp_path, text, "stuck.xml")
    assert errors(path) == [at(path, text, '<function name="wait_flag">', (
        "wait_flag('done_c') of right_arm can never end: no other group sets flag 'done_c' (no set_flag of that name in the application) (in for_each v=c)"
    ))]


def test_what_substitution_makes_is_held_to_what_may_be_written(tmp_path: Path) -> None:
    block_text = block().replace('id="d_{hole}"', 'id="d_{hole}_{hole}"')
    (tmp_path / "blk.xml").write_text(block_text)
    long = "x" * 40
    text = app(f'  <call application="blk.xml"><param name="hole" value="{long}"/></call>\n'
               '  <call application="blk.xml"><param name="hole" value="a b"/></call>\n'
               '  <for_each var="s" in="a&#x202E;b">\n' + op("o_{s}", "left_arm", "gripper_open") + "  </for_each>\n")
    path = write(tmp_path, text)
    found = errors(path)
    assert at(tmp_path / "blk.xml", block_text, 'id="d_', (
        f"operation id 'd_{{hole}}_{{hole}}' comes out 83 characters long, more than 64 (in call blk.xml hole={long} at {path}:3)"
    )) in found
    assert at(tmp_path / "blk.xml", block_text, 'id="d_', (
        f"operation id 'd_{{hole}}_{{hole}}' comes out 'd_a b_a b', which holds a space; an id needs letters, digits and punctuation (in call blk.xml hole=a b at {path}:4)"
    )) in found
    assert at(path, text, 'id="o_{s}"', (
        "operation id 'o_{s}' comes out 'o_a\\u202eb', which holds RIGHT-TO-LEFT OVERRIDE (U+202E); an id needs letters, digits and punctuation (in for_each s=a\\u202eb)"
    )) in found


def test_what_a_called_file_says_that_does_not_apply_is_a_warning(tmp_path: Path) -> None:
    (tmp_path / "blk.xml").write_text(block(extra='<error_policy action="alarm"/>\n').replace('robot="nextage"', 'robot="nextage" sync="flags"'))
    text = app('  <call application="blk.xml"><param name="hole" value="drill_1"/><param name="slot" value="rivet_1"/></call>\n')
    path = write(tmp_path, text)
    assert errors(path) == [
        at(path, text, 'application="', 'warning: blk.xml says sync="flags", this application sync="operation": its operations run as this one\'s do'),
        at(path, text, 'application="', "warning: the <error_policy> of blk.xml does not apply: the calling application's does"),
        at(path, text, 'name="slot"', "warning: blk.xml uses no variable {slot} (it uses: hole)"),
    ]
    assert [o.id for o in load_application(path, CATALOG).operations] == ["d_drill_1"]


def test_a_variable_may_have_any_name_the_schema_allows(tmp_path: Path) -> None:
    text = app('  <for_each var="hole.id-2" in="drill_1">\n' + op("d_{hole.id-2}", "left_arm", "debur_drilling", "{hole.id-2}") + "  </for_each>\n")
    loaded = load_application(write(tmp_path, text), CATALOG)
    assert [(o.id, o.calls["left_arm"].params[0]) for o in loaded.operations] == [("d_drill_1", "drill_1")]
