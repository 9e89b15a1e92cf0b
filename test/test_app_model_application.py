"""Application files: the model a clean file yields, and every kind of mistake at its FILE:LINE:COL."""
from __future__ import annotations

from pathlib import Path

import pytest
from app_model_support import APP_XML, CELL_XML, at, small_catalog

from core_functions.catalog import Catalog, ParamSpec, ParamType, skill
from execution_engine.app_model import (
    ApplicationError,
    Diagnostic,
    ErrorPolicy,
    load_application,
    validate_application,
)

CATALOG = small_catalog()


def app(body: str, *, robot: str = "nextage", cell: str | None = "cells/rivet_cell.xml", head: str = "") -> str:
    cell_attr = f' cell="{cell}"' if cell else ""
    return f'<?xml version="1.0" encoding="UTF-8"?>\n<application name="t" robot="{robot}"{cell_attr}>\n{head}{body}</application>\n'


@pytest.fixture
def work(tmp_path: Path) -> Path:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    return tmp_path


def write(work: Path, text: str, name: str = "app.xml") -> Path:
    path = work / name
    path.write_text(text)
    return path


def check(work: Path, text: str, catalog: Catalog = CATALOG) -> tuple[Path, list[str]]:
    path = write(work, text)
    return path, [str(d) for d in validate_application(path, catalog)]


# ------------------------------------------------------------------------------ a clean file
def test_clean_application_has_no_diagnostics_and_a_complete_model(work: Path) -> None:
    path = write(work, APP_XML)
    assert validate_application(path, CATALOG) == []
    application = load_application(path, CATALOG)
    assert application.name == "rivet_installation"
    assert application.robot.name == "nextage_open"  # the alias "nextage" resolved
    assert application.description == "Debur a hole and install a rivet"
    assert application.error_policy == ErrorPolicy(retries=1, action="safe_pose", safe_pose="initial", alarm_timeout=0.0)
    assert [op.id for op in application.operations] == ["1", "2", "3"]
    first = application.operations[0]
    assert list(first.calls) == ["left_arm", "right_arm", "torso_head"]  # the robot's group order
    debur = first.calls["left_arm"]
    assert (debur.function, debur.params, debur.implicit) == ("debur_drilling", ("drill_1",), False)
    assert (debur.file, debur.line, debur.col) == (str(path), 7, 7)
    assert first.calls["right_arm"].params == ("rivet_1", "ref_R10")
    assert first.calls["torso_head"].function == "wait" and not first.calls["torso_head"].implicit
    second = application.operations[1]
    assert second.name == "insert" and (second.line, second.col) == (20, 3)
    # Groups left out wait, marked implicit, located at their operation.
    left = second.calls["left_arm"]
    assert (left.function, left.params, left.implicit, left.line, left.col) == ("wait", (), True, 20, 3)
    # Optional params left out are filled with their defaults.
    assert application.operations[2].calls["left_arm"].params == ("drill_2", "0.5")
    assert application.cell is not None and application.cell.robot is application.robot
    assert application.cell.to_snapshot().joint_poses["left_ready"]["LARM_JOINT2"] == pytest.approx(-1.745329, abs=1e-6)


def test_load_raises_with_every_diagnostic(work: Path) -> None:
    text = app('<operation id="1"><left_arm><function name="nope"/></left_arm></operation>\n'
               '<operation id="1"><left_arm><function name="wait"/></left_arm></operation>\n')
    path = write(work, text)
    with pytest.raises(ApplicationError) as caught:
        load_application(path, CATALOG)
    assert [str(d) for d in caught.value.diagnostics] == [
        at(path, text, 'name="nope"', "unknown function 'nope'"),
        at(path, text, 'id="1"', "operation id '1' is used twice (first on line 3)", occurrence=2),
    ]
    assert str(caught.value).startswith("2 error(s)\n")


# ------------------------------------------------------------------------------ functions and params
def test_unknown_function_suggests_the_closest_name(work: Path) -> None:
    text = app('<operation id="1">\n  <left_arm><function name="debur_driling"><params><param value="drill_1"/></params></function></left_arm>\n</operation>\n')
    path, found = check(work, text)
    assert found == [f"{path}:4:23: unknown function 'debur_driling' (did you mean 'debur_drilling'?)"]
    assert found == [at(path, text, 'name="debur_driling"', "unknown function 'debur_driling' (did you mean 'debur_drilling'?)")]


def test_wrong_number_of_params_points_at_the_function(work: Path) -> None:
    text = app('<operation id="1"><left_arm>\n  <function name="debur_drilling"/>\n</left_arm></operation>\n')
    path, found = check(work, text)
    assert found == [f"{path}:4:3: debur_drilling(hole) takes 1 params, got 0"]


def test_too_many_params(work: Path) -> None:
    text = app('<operation id="1"><left_arm><function name="move_to"><params>'
               '<param value="drill_1"/><param value="0.5"/><param value="3"/></params></function></left_arm></operation>\n')
    path, found = check(work, text)
    assert found == [at(path, text, "<function", "move_to(target, speed=0.5) takes 1 to 2 params, got 3")]


def test_param_type_unit_and_range_errors_point_at_the_value(work: Path) -> None:
    text = app(
        '<operation id="1">\n'
        '  <left_arm><function name="move_to"><params><param value="drill_1"/><param value="1.5"/></params></function></left_arm>\n'
        '  <right_arm><function name="move_to"><params><param value="drill_1"/><param value="fast"/></params></function></right_arm>\n'
        '  <torso_head><function name="look"><params><param value="10 mm"/></params></function></torso_head>\n'
        '</operation>\n'
    )
    path, found = check(work, text)
    assert found == [
        at(path, text, 'value="1.5"', "param 2 (speed) of move_to: 1.5 fraction is above the maximum 1"),
        at(path, text, 'value="fast"', "param 2 (speed) of move_to: 'fast' is not a number (unit fraction)"),
        at(path, text, 'value="10 mm"', "param 1 (pan) of look: unit 'mm' does not fit this parameter (unit rad; suffixes: 'deg', 'rad')"),
    ]


def test_joint_values_are_checked_against_the_group(work: Path) -> None:
    text = app('<operation id="1">\n'
               '  <right_arm><function name="move_joints"><params><param value="0 0 0 0 0 400deg"/></params></function></right_arm>\n'
               '  <left_arm><function name="move_joints"><params><param value="0 0 0"/></params></function></left_arm>\n'
               '</operation>\n')
    path, found = check(work, text)
    assert found == [
        at(path, text, 'value="0 0 0 0', "param 1 (joints) of move_joints: RARM_JOINT5 = 400.00 deg is outside its limits [-163.0, 163.0] deg"),
        at(path, text, 'value="0 0 0"/>', "param 1 (joints) of move_joints: 3 joint values for left_arm, which has 6 joints "
           "(LARM_JOINT0, LARM_JOINT1, LARM_JOINT2, LARM_JOINT3, LARM_JOINT4, LARM_JOINT5)"),
    ]


def test_param_names_must_match_the_position(work: Path) -> None:
    text = app('<operation id="1">\n'
               '  <left_arm><function name="move_to"><params><param name="speed" value="0.2"/><param name="target" value="drill_1"/></params></function></left_arm>\n'
               '  <right_arm><function name="move_to"><params><param name="goal" value="drill_1"/></params></function></right_arm>\n'
               '</operation>\n')
    path, found = check(work, text)
    message = ("param {i} is named '{n}', but move_to takes '{n}' as param {j} and '{o}' here: "
               "params bind by position (move_to(target, speed=0.5))")
    assert found == [
        at(path, text, 'name="speed"', message.format(i=1, n="speed", j=2, o="target")),
        # 0.2 is also not a target: reported too, so a user fixing the names sees the whole picture.
        at(path, text, 'value="0.2"', "param 1 (target) of move_to: '0.2' is neither a frame name nor 6 numbers x,y,z,roll,pitch,yaw"),
        at(path, text, 'name="target"', message.format(i=2, n="target", j=1, o="speed")),
        at(path, text, 'value="drill_1"/></params></function></left_arm>', "param 2 (speed) of move_to: 'drill_1' is not a number (unit fraction)"),
        at(path, text, 'name="goal"', "move_to has no param named 'goal'; its params are move_to(target, speed=0.5)"),
    ]


def test_correctly_named_params_are_accepted(work: Path) -> None:
    text = app('<operation id="1"><left_arm><function name="move_to"><params>'
               '<param name="target" value="drill_1"/><param name="speed" value="20%"/></params></function></left_arm></operation>\n')
    path = write(work, text)
    assert load_application(path, CATALOG).operations[0].calls["left_arm"].params == ("drill_1", "20%")


def test_function_that_cannot_run_on_the_group_kind(work: Path) -> None:
    text = app('<operation id="1">\n  <torso_head><function name="move_to"><params><param value="drill_1"/></params></function></torso_head>\n</operation>\n')
    path, found = check(work, text)
    assert found == [f"{path}:4:15: move_to cannot run on torso_head (a torso_head group); it runs on: arm"]


def test_group_of_another_robot(work: Path) -> None:
    text = app('<operation id="1">\n  <arm><function name="wait"/></arm>\n</operation>\n')
    path, found = check(work, text)
    assert found == [f"{path}:4:3: arm is not a group of nextage_open (its groups: left_arm, right_arm, torso_head)"]


def test_unknown_robot(work: Path) -> None:
    text = app('<operation id="1"><arm><function name="wait"/></arm></operation>\n', robot="r2d2")
    path, found = check(work, text)
    assert found == [f"{path}:2:23: unknown robot 'r2d2' (known: adept_viper_s850, kuka, kuka_kr, kuka_rsi, nextage, nextage_open, viper, vplus)"]


# ------------------------------------------------------------------------------ the cell
def test_unknown_frame_element_and_joint_pose(work: Path) -> None:
    text = app('<operation id="1">\n'
               '  <left_arm><function name="debur_drilling"><params><param value="dril_1"/></params></function></left_arm>\n'
               '  <right_arm><function name="pick_rivet"><params><param value="rivet_1"/><param value="ref_R11"/></params></function></right_arm>\n'
               '  <torso_head><function name="go_to_pose"><params><param value="nowhere"/></params></function></torso_head>\n'
               '</operation>\n')
    path, found = check(work, text)
    assert found == [
        at(path, text, 'value="dril_1"', "param 1 (hole) of debur_drilling: unknown frame 'dril_1' in the cell model (did you mean 'drill_1'?)"),
        at(path, text, 'value="ref_R11"', "param 2 (element) of pick_rivet: unknown element 'ref_R11' in the cell model"),
        at(path, text, 'value="nowhere"', "param 1 (pose) of go_to_pose: unknown joint pose 'nowhere' (robot poses: initial, off; or a <joint_pose> of the cell)"),
    ]


def test_frame_of_the_wrong_kind(work: Path) -> None:
    text = app('<operation id="1"><right_arm><function name="pick_rivet"><params>'
               '<param value="drill_1"/><param value="ref_R10"/></params></function></right_arm></operation>\n')
    path, found = check(work, text)
    assert found == [at(path, text, 'value="drill_1"', "param 1 (slot) of pick_rivet: frame 'drill_1' is a hole, expected rivet_slot")]


def test_frame_reference_without_a_cell(work: Path) -> None:
    text = app('<operation id="1"><left_arm><function name="debur_drilling"><params><param value="drill_1"/></params></function></left_arm></operation>\n', cell=None)
    path, found = check(work, text)
    assert found == [at(path, text, 'value="drill_1"', "param 1 (hole) of debur_drilling: frame 'drill_1' needs a cell model, and the application names none")]


def test_group_joint_pose_used_by_another_group(work: Path) -> None:
    text = app('<operation id="1">\n'
               '  <left_arm><function name="go_to_pose"><params><param value="left_ready"/></params></function></left_arm>\n'
               '  <right_arm><function name="go_to_pose"><params><param value="left_ready"/></params></function></right_arm>\n'
               '</operation>\n')
    path, found = check(work, text)
    assert found == [at(path, text, 'value="left_ready"', "param 1 (pose) of go_to_pose: joint pose 'left_ready' is for left_arm, not right_arm", occurrence=2)]


def test_missing_cell_file(work: Path) -> None:
    text = app('<operation id="1"><left_arm><function name="debur_drilling"><params><param value="drill_1"/></params></function></left_arm></operation>\n', cell="cells/none.xml")
    path, found = check(work, text)
    # References into the missing cell are not reported one by one: the cause is the file.
    assert found == [at(path, text, 'cell="', f"cell file {work}/cells/none.xml not found (looked for {(work / 'cells' / 'none.xml').resolve()})")]


def test_invalid_cell_is_reported_with_its_own_path_and_lines(work: Path) -> None:
    cell_text = CELL_XML.replace('parent="world" xyz="0.35', 'parent="wrld" xyz="0.35')
    (work / "cells" / "rivet_cell.xml").write_text(cell_text)
    text = app('<operation id="1"><left_arm><function name="debur_drilling"><params><param value="drill_1"/></params></function></left_arm></operation>\n')
    path, found = check(work, text)
    cell_path = work / "cells" / "rivet_cell.xml"
    assert found == [  # sorted by file name: app.xml before cells/
        at(path, text, 'cell="', "cell file " + str(cell_path) + " has errors (listed with its name); references to its frames are not checked until they are fixed"),
        at(cell_path, cell_text, 'parent="wrld"', "frame 'rivet_tray': unknown parent frame 'wrld' (did you mean 'world'?)"),
    ]


def test_cell_joint_poses_are_checked_against_the_robot(work: Path) -> None:
    cell_text = CELL_XML.replace('joints="0 0 0  -0.6 0 -100 15.2 9.4 3.2  0.6', 'joints="0 0 0  -0.6 0 -100 15.2 9.4 0.6')
    (work / "cells" / "rivet_cell.xml").write_text(cell_text)
    path, found = check(work, app('<operation id="1"><left_arm><function name="wait"/></left_arm></operation>\n'))
    cell_path = work / "cells" / "rivet_cell.xml"
    assert found == [
        at(cell_path, cell_text, 'joints="0 0 0  -0.6 0 -100 15.2 9.4 0.6', "joint pose 'safe' has 14 values; nextage_open has 15 joints, in this order: "
           "CHEST_JOINT0 HEAD_JOINT0 HEAD_JOINT1 RARM_JOINT0 RARM_JOINT1 RARM_JOINT2 RARM_JOINT3 RARM_JOINT4 RARM_JOINT5 "
           "LARM_JOINT0 LARM_JOINT1 LARM_JOINT2 LARM_JOINT3 LARM_JOINT4 LARM_JOINT5"),
    ]


# ------------------------------------------------------------------------------ structure
def test_duplicate_operation_ids_and_repeated_groups(work: Path) -> None:
    text = app('<operation id="1">\n'
               '  <left_arm><function name="wait"/></left_arm>\n'
               '  <left_arm><function name="wait"/></left_arm>\n'
               '</operation>\n'
               '<operation id="1"><left_arm><function name="wait"/></left_arm></operation>\n')
    path, found = check(work, text)
    assert found == [
        f"{path}:5:3: group left_arm appears twice in operation 1 (first on line 4)",
        f"{path}:7:12: operation id '1' is used twice (first on line 3)",
    ]


def test_schema_errors_in_plain_words(work: Path) -> None:
    text = app(
        '<operation id="1">\n'
        '  <left_amr><function name="wait"/></left_amr>\n'
        '  <right_arm><function name="wait"/><function name="wait"/></right_arm>\n'
        '  <torso_head><function nme="wait"/></torso_head>\n'
        '</operation>\n'
        '<operation>\n'
        '  <left_arm><function name="move_to"><params><param value="drill_1">x</param><param/></params></function></left_arm>\n'
        '</operation>\n'
        '<description>late</description>\n',
        head='<error_policy retries="-1" action="retry"/>\n',
    )
    path, found = check(work, text)
    assert found == [
        at(path, text, 'retries=', "attribute retries='-1' of <error_policy>: expected a whole number, 0 or more"),
        at(path, text, 'action=', "attribute action='retry' of <error_policy>: expected one of abort, safe_pose, alarm"),
        at(path, text, "<left_amr", "<left_amr> is not allowed here inside <operation>; expected <left_arm>, <right_arm>, <torso_head> or <arm> (did you mean <left_arm>?)"),
        at(path, text, '<function name="wait"/></right_arm>', "<function> is not allowed here inside <right_arm> "
           "(a group runs exactly one <function> per operation; put the next one in a new <operation>)"),
        at(path, text, "<function nme", "<function> needs the attribute name"),
        at(path, text, "nme=", "<function> has no attribute nme (did you mean name?); it takes: name"),
        at(path, text, "<operation>", "<operation> needs the attribute id"),
        at(path, text, '<param value="drill_1">', "<param> cannot contain text; write values as attributes"),
        at(path, text, "<param/>", "<param> needs the attribute value"),
        at(path, text, "<description>", "<description> is not allowed here inside <application>; expected <operation>, <for_each>, <repeat> or <call> "
           "(<description> and <error_policy> come before the first <operation>, at most once each)"),
    ]


def test_description_holds_text_only(work: Path) -> None:
    text = app('<operation id="1"><left_arm><function name="wait"/></left_arm></operation>\n',
               head="<description>Rivets <b>fast</b></description>\n")
    path, found = check(work, text)
    assert found == [at(path, text, "<description>", "<description> holds text only, no elements")]


def test_wrong_root_element(work: Path) -> None:
    path, found = check(work, '<cell name="x"/>\n')
    assert found == [f"{path}:1:1: the root element is <cell>; this file must start with <application>"]


def test_application_without_operations(work: Path) -> None:
    path, found = check(work, app(""))
    assert found == [f"{path}:2:1: <application> needs at least one <operation>"]


def test_many_errors_at_once_sorted_by_position(work: Path) -> None:
    lines = "".join(
        f'<operation id="{i}"><left_arm><function name="nope{i}"/></left_arm></operation>\n' for i in range(1, 51)
    )
    text = app(lines)
    path, found = check(work, text)
    assert found == [at(path, text, f'name="nope{i}"', f"unknown function 'nope{i}'") for i in range(1, 51)]
    assert found[0] == f"{path}:3:39: unknown function 'nope1'"


# ------------------------------------------------------------------------------ synchronisation
def test_full_body_function_needs_every_arm_with_the_same_params(work: Path) -> None:
    good = app('<operation id="1">\n'
               '  <left_arm><function name="full_body_move"><params><param value="safe"/></params></function></left_arm>\n'
               '  <right_arm><function name="full_body_move"><params><param value="safe"/></params></function></right_arm>\n'
               '</operation>\n')
    assert check(work, good)[1] == []  # torso_head left out: it waits, which is allowed
    bad = app('<operation id="1">\n'
              '  <left_arm><function name="full_body_move"><params><param value="safe"/></params></function></left_arm>\n'
              '  <right_arm><function name="full_body_move"><params><param value="initial"/></params></function></right_arm>\n'
              '  <torso_head><function name="go_to_pose"><params><param value="safe"/></params></function></torso_head>\n'
              '</operation>\n'
              '<operation id="2">\n'
              '  <right_arm><function name="full_body_move"><params><param value="safe"/></params></function></right_arm>\n'
              '</operation>\n')
    path, found = check(work, bad)
    assert found == [
        at(path, bad, "<function", "full_body_move(safe) on left_arm is a full-body function: right_arm must call it too with the same params, "
           "but calls full_body_move(initial)", occurrence=2),
        at(path, bad, "<function", "full_body_move(safe) on left_arm is a full-body function: torso_head must call it too with the same params, "
           "or wait, but calls go_to_pose(safe)", occurrence=3),
        at(path, bad, "<function", "full_body_move(safe) on right_arm is a full-body function: left_arm must call it too with the same params, "
           "but it is left out of operation 2", occurrence=4),
    ]


def test_master_and_slave_must_name_each_other(work: Path) -> None:
    good = app('<operation id="1">\n'
               '  <left_arm><function name="master_move"><params><param value="drill_1"/><param value="right_arm"/></params></function></left_arm>\n'
               '  <right_arm><function name="slave_follow"><params><param value="left_arm"/></params></function></right_arm>\n'
               '</operation>\n')
    assert check(work, good)[1] == []
    bad = app('<operation id="1">\n'
              '  <left_arm><function name="master_move"><params><param value="drill_1"/><param value="right_arm"/></params></function></left_arm>\n'
              '</operation>\n'
              '<operation id="2">\n'
              '  <left_arm><function name="master_move"><params><param value="drill_1"/><param value="right_arm"/></params></function></left_arm>\n'
              '  <right_arm><function name="master_move"><params><param value="drill_2"/><param value="left_arm"/></params></function></right_arm>\n'
              '</operation>\n'
              '<operation id="3">\n'
              '  <left_arm><function name="slave_follow"><params><param value="torso_head"/></params></function></left_arm>\n'
              '  <right_arm><function name="slave_follow"><params><param value="left_arm"/></params></function></right_arm>\n'
              '</operation>\n')
    path, found = check(work, bad)
    assert found == [
        at(path, bad, "<function", "master_move on left_arm names right_arm as its slave, but right_arm is left out of operation 1; "
           "it must call the matching master/slave function naming left_arm", occurrence=1),
        at(path, bad, "<function", "left_arm and right_arm are both masters in operation 2: one arm leads (master), the other follows (slave)", occurrence=2),
        at(path, bad, "<function", "slave_follow on left_arm names torso_head as its master, but torso_head is left out of operation 3; "
           "it must call the matching master/slave function naming left_arm", occurrence=4),
        at(path, bad, "<function", "slave_follow on right_arm names left_arm, but left_arm's slave_follow names torso_head: they must name each other", occurrence=5),
    ]


# ------------------------------------------------------------------------------ plausibility
def test_hold_plausibility_across_operations(work: Path) -> None:
    pick = '<right_arm><function name="pick_rivet"><params><param value="rivet_1"/><param value="ref_R10"/></params></function></right_arm>'
    insert = '<right_arm><function name="insert_rivet"><params><param value="drill_1"/></params></function></right_arm>'
    text = app(
        f'<operation id="1">{insert}</operation>\n'  # line 3: nothing picked yet
        f'<operation id="2">{pick}</operation>\n'
        '<operation id="3"><left_arm><function name="wait"/></left_arm></operation>\n'  # right_arm waits, still holding
        f'<operation id="4">{insert}</operation>\n'  # fine
        f'<operation id="5">{insert}</operation>\n'  # line 7: nothing since operation 4
        f'<operation id="6">{pick}</operation>\n'
        f'<operation id="7">{pick}</operation>\n'  # line 9: hand is full
    )
    path, found = check(work, text)
    assert found == [
        f"{path}:3:30: insert_rivet needs the right_arm to hold a part, but nothing was picked since the start of the application",
        f"{path}:7:30: insert_rivet needs the right_arm to hold a part, but nothing was picked since operation 4 (line 6), where insert_rivet left it empty",
        f"{path}:9:30: pick_rivet needs the right_arm's hand to be empty, but it still holds what pick_rivet took in operation 6 (line 8)",
    ]


def test_unknown_hold_disables_the_check_until_a_known_hold(work: Path) -> None:
    insert = '<right_arm><function name="insert_rivet"><params><param value="drill_1"/></params></function></right_arm>'
    text = app(
        '<operation id="1"><right_arm><function name="close_gripper"/></right_arm></operation>\n'
        f'<operation id="2">{insert}</operation>\n'  # unknown: not checked; leaves nothing
        f'<operation id="3">{insert}</operation>\n'  # checked again: error
        '<operation id="4"><right_arm><function name="open_gripper"/></right_arm></operation>\n'
    )
    path, found = check(work, text)
    assert found == [f"{path}:5:30: insert_rivet needs the right_arm to hold a part, but nothing was picked since operation 2 (line 4), where insert_rivet left it empty"]


# ------------------------------------------------------------------------------ error policy
def test_error_policy_defaults_and_safe_pose_lookup(work: Path) -> None:
    op = '<operation id="1"><left_arm><function name="wait"/></left_arm></operation>\n'
    assert load_application(write(work, app(op)), CATALOG).error_policy == ErrorPolicy(safe_pose="initial")
    from_cell = app(op, head='<error_policy action="alarm" safe_pose="safe" alarm_timeout="2.5" retries="3"/>\n')
    assert load_application(write(work, from_cell), CATALOG).error_policy == ErrorPolicy(3, "alarm", "safe", 2.5)
    unknown = app(op, head='<error_policy action="safe_pose" safe_pose="nowhere"/>\n')
    path, found = check(work, unknown)
    assert found == [at(path, unknown, "safe_pose=", "unknown safe_pose 'nowhere' (robot poses: initial, off; cell joint poses: left_ready, safe)")]


def test_safe_pose_action_needs_a_pose_on_robots_without_initial(work: Path) -> None:
    text = app('<operation id="1"><arm><function name="wait"/></arm></operation>\n', robot="viper", cell=None,
               head='<error_policy action="safe_pose"/>\n')
    path, found = check(work, text)
    assert found == [f"{path}:3:1: error_policy action safe_pose needs a safe_pose: adept_viper_s850 has no 'initial' pose "
                     "(its poses: home; or a <joint_pose> of the cell)"]
    fixed = load_application(write(work, text.replace('action="safe_pose"', 'action="safe_pose" safe_pose="home"')), CATALOG)
    assert fixed.error_policy.safe_pose == "home"
    assert list(fixed.operations[0].calls) == ["arm"]


# ------------------------------------------------------------------------------ wait without a catalog entry
class _NoWait:
    @skill(ParamSpec("duration", ParamType.NUMBER, "how long", unit="s"))
    def sleep(self, duration: float) -> None:
        """Pause."""


def test_wait_is_built_in_when_the_catalog_has_none(work: Path) -> None:
    catalog = Catalog.from_classes({"core": _NoWait})
    text = app('<operation id="1"><left_arm><function name="wait"/></left_arm>\n'
               '<right_arm><function name="wait"><params><param value="1"/></params></function></right_arm></operation>\n', cell=None)
    path, found = check(work, text, catalog)
    assert found == [at(path, text, '<param value="1"', "wait takes no params")]
    application = load_application(write(work, app('<operation id="1"><left_arm><function name="wait"/></left_arm></operation>\n', cell=None)), catalog)
    assert application.operations[0].calls["right_arm"].implicit


def test_diagnostic_format() -> None:
    assert str(Diagnostic("a.xml", 3, 7, "bad")) == "a.xml:3:7: bad"
    assert str(Diagnostic("a.xml", 3, 7, "odd", "warning")) == "a.xml:3:7: warning: odd"
