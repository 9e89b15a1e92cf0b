"""The dry run checks every side of every <if> (issue 24 item 2): it says which outcomes each pass
assumed, and a collision on the side the simulator would not take is found before anything moves."""
from __future__ import annotations

from pathlib import Path

from test_dry_run import cli, findings

ROOT = Path(__file__).resolve().parent.parent
BRANCH = ROOT / "apps_xml" / "rivet_loop_branch.xml"
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
MISSING = ROOT / "apps_xml" / "examples" / "cells" / "rivet_cell_hole_missing.xml"
PUT_BACK = '<right_arm><function name="place"><params><param value="rivet_{index}"/></params></function></right_arm>'
#: Where the right arm would put the rivet back: right beside the left arm, which stands above the hole it did not find.
INTO_THE_LEFT_ARM = '<right_arm><function name="place"><params><param value="0.34,-0.02,-0.004,3.14159265,0,0"/></params></function></right_arm>'
PASS_1 = "  branches, pass 1 (the prediction): assumed " + ", ".join(f"look_drill_{n} left_arm found" for n in range(1, 5))
PASS_2 = "  branches, pass 2: assumed " + ", ".join(f"look_drill_{n} left_arm not_found" for n in range(1, 5))


def branch_app(folder: Path, put_back: str = PUT_BACK, cell: Path = CELL) -> Path:
    text = BRANCH.read_text()
    assert text.count(PUT_BACK) == 1
    app = folder / "app.xml"
    app.write_text(text.replace(PUT_BACK, put_back).replace('cell="cells/rivet_cell.xml"', f'cell="{cell}"'))
    return app


def test_the_branch_demonstrator_is_dry_run_on_both_sides_of_its_if(tmp_path: Path) -> None:
    code, out, err = cli("validate", "--simulate", str(branch_app(tmp_path)), "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 0, out + err
    assert "no problems found; operations checked 22/22" in out  # the found side's 18 and the put-backs: every operation
    assert PASS_1 in out.splitlines() and PASS_2 in out.splitlines()
    assert "assumed against the simulated cell" not in out  # every hole there: the simulator agrees with each pass


def test_a_collision_on_the_side_the_simulator_would_not_take_is_found_before_anything_moves(tmp_path: Path) -> None:
    app = branch_app(tmp_path, INTO_THE_LEFT_ARM)
    line = next(n for n, text in enumerate(app.read_text().splitlines(), start=1) if INTO_THE_LEFT_ARM in text)
    db = str(tmp_path / "t.sqlite")
    code, out, err = cli("validate", "--simulate", str(app), "--trajectory-db", db)
    assert code == 1, out + err
    found = findings(err)
    at_place = [f for f in found if f.startswith(f"{app}:{line}:") and " right_arm place: collision: " in f]
    assert {f.split(" operation ")[1].split(" ")[0] for f in at_place} >= {f"put_back_drill_{n}" for n in range(2, 5)}, err
    assert all(f.endswith(f"; assuming {PASS_2.split('assumed ')[1]})") for f in found), "only the not_found side meets it"
    assert PASS_1 in out.splitlines() and PASS_2 in out.splitlines()
    code, out, err = cli("run", str(app), "--speed", "max", "-q", "--trajectory-db", db)
    assert code == 1
    assert f"{app}: not run: {len(found)} problem(s) found by the dry run; use --no-check to run anyway" in err
    assert "application rivet_loop_branch" not in out  # nothing was started


#: The found side's insert with the left arm coming down over the hole the right arm inserts into.
INSERT_BESIDE = '<operation id="insert_{hole}" name="insert {index}">\n        <left_arm><function name="wait"/></left_arm>'
LEFT_ARM_OVER_IT = INSERT_BESIDE.replace('<function name="wait"/>', '<function name="approach"><params><param value="{hole}"/><param value="0.02"/></params></function>')


def test_on_the_cell_without_drill_3_the_found_side_s_motions_are_still_checked_for_collisions(tmp_path: Path) -> None:
    """The pass assuming drill_3 found meets a cell without it: the found side's vision of drill_3 is not checked
    (a note), but its motions are, at drill_3's nominal pose -- a collision there refuses the run as anywhere."""
    app = branch_app(tmp_path, cell=MISSING)
    app.write_text(app.read_text().replace(INSERT_BESIDE, LEFT_ARM_OVER_IT))
    line = next(n for n, text in enumerate(app.read_text().splitlines(), start=1) if 'name="insert_rivet"' in text)
    db = str(tmp_path / "t.sqlite")
    code, out, err = cli("validate", "--simulate", str(app), "--trajectory-db", db)
    assert code == 1, out + err
    found = findings(err)
    at_3 = [f for f in found if f.startswith(f"{app}:{line}:20: operation insert_drill_3 (for_each hole=drill_3) right_arm insert_rivet: collision: ")]
    assert len(at_3) == 1 and at_3[0].endswith(f"; assuming {PASS_1.split('assumed ')[1]})"), err
    assert not [f for f in found if ": vision: " in f], "drill_3's vision on the found side is the assumption's consequence, not a finding"
    assert "  assumed against the simulated cell: look_drill_3 left_arm assumed found where the simulated cell ended it not_found" in out
    code, out, err = cli("run", str(app), "--speed", "max", "-q", "--trajectory-db", db)
    assert code == 1 and f"{app}: not run: {len(found)} problem(s) found by the dry run; use --no-check to run anyway" in err
    assert "application rivet_loop_branch" not in out  # nothing was started


def test_a_look_at_the_missing_hole_outside_the_side_that_assumed_it_found_is_still_refused(tmp_path: Path) -> None:
    """Only the side of the <if> whose assumption the cell contradicts is excused: the same hole deburred after
    the loop, whatever look_drill_3 found, fails in the real run too -- a finding, on the cell without drill_3."""
    app = branch_app(tmp_path, cell=MISSING)
    again = '<operation id="again"><left_arm><function name="debur_drilling"><params><param value="drill_3"/></params></function></left_arm></operation>\n'
    app.write_text(app.read_text().replace('  <operation id="home"', f"  {again}  <operation id=\"home\"", 1))
    line = next(n for n, text in enumerate(app.read_text().splitlines(), start=1) if 'id="again"' in text)
    code, out, err = cli("validate", "--simulate", str(app), "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1, out + err
    found = findings(err)
    assert found and all(f.startswith(f"{app}:{line}:") and " left_arm debur_drilling: vision: " in f and "drill_3: no hole" in f for f in found), err
    assert "by debur_drill_3 left_arm debur_drilling, insert_drill_3 right_arm insert_rivet not checked" in out  # the side itself, as before


def test_a_side_whose_assumption_the_cell_agrees_with_still_has_its_vision_checked(tmp_path: Path) -> None:
    """The not_found side inserting its rivet into the hole it did not find: on the cell without drill_3 the pass
    assuming not_found agrees with the cell, so the side's vision of drill_3 failing is a finding, as in the real run."""
    into_the_hole = '<right_arm><function name="insert_rivet"><params><param value="{hole}"/></params></function></right_arm>'
    app = branch_app(tmp_path, into_the_hole, cell=MISSING)
    line = [n for n, text in enumerate(app.read_text().splitlines(), start=1) if into_the_hole in text][-1]  # the <else>'s, after the found side's
    code, out, err = cli("validate", "--simulate", str(app), "--trajectory-db", str(tmp_path / "t.sqlite"))
    assert code == 1, out + err
    vision = [f for f in findings(err) if ": vision: " in f]  # (the left arm, still over the hole, is in the way too)
    assert len(vision) == 1 and vision[0].startswith(f"{app}:{line}:20: operation put_back_drill_3 (for_each hole=drill_3) right_arm insert_rivet: vision: "), err
    assert vision[0].endswith(f"; assuming {PASS_2.split('assumed ')[1]})") and "drill_3: no hole" in vision[0]
