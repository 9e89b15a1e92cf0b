"""Values that parse but cannot be physical are refused where they are written, with the bound.

A frame 1e308 m away or a roll of 1e308 deg used to validate and then overflow at run time; an
inline target of 1e308 rad ran to a meaningless roll.  Every length, angle, speed, fraction and
duration is held to core_functions.limits, one table read by the cell reader, the application
reader and the catalog alike.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from app_model_support import APP_XML, CELL_XML, at, small_catalog

from core_functions import limits
from core_functions.catalog import BindContext
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import ApplicationError, load_application, load_cell, validate_application, validate_cell

CATALOG = small_catalog()


def cell_file(tmp_path: Path, body: str, units: str = "") -> tuple[Path, str]:
    text = f'<?xml version="1.0"?>\n<cell name="c"{units}>\n{body}</cell>\n'
    path = tmp_path / "cell.xml"
    path.write_text(text)
    return path, text


@pytest.fixture
def work(tmp_path: Path) -> Path:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    return tmp_path


# ------------------------------------------------------------------------------ the cell
def test_a_frame_1e308_m_away_is_refused_at_its_xyz(tmp_path: Path) -> None:
    path, text = cell_file(tmp_path, '  <frame name="far" xyz="1e308 0 0"/>\n')
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'xyz="1e308', "xyz of <frame> 'far': x = 1e+308 m is outside ±100 m, the bound of a length in a cell"),
    ]
    with pytest.raises(ApplicationError):
        load_cell(path)


def test_an_rpy_of_1e308_deg_is_refused_in_degrees(tmp_path: Path) -> None:
    path, text = cell_file(tmp_path, '  <frame name="spun" rpy="0 1e308 0"/>\n', ' angle_unit="deg"')
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'rpy="', "rpy of <frame> 'spun': pitch = 1e+308 deg is outside ±720 deg, the bound of an angle (two turns)"),
    ]


def test_millimetre_cells_are_bounded_in_millimetres(tmp_path: Path) -> None:
    body = '  <frame name="ok" xyz="99999 0 0"/>\n  <frame name="far" xyz="0 -100001 0"/>\n'
    path, text = cell_file(tmp_path, body, ' length_unit="mm"')
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'xyz="0 -100001', "xyz of <frame> 'far': y = -100001 mm is outside ±100000 mm, the bound of a length in a cell"),
    ]


def test_an_actual_offset_is_bounded_too(tmp_path: Path) -> None:
    path, text = cell_file(tmp_path, '  <frame name="part">\n    <actual rpy="30 0 0"/>\n  </frame>\n')
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'rpy="30', "rpy of <actual> of frame 'part': roll = 30 rad is outside ±12.5664 rad, the bound of an angle (two turns)"),
    ]


def test_offsets_that_add_up_beyond_the_cell_are_refused_once_at_the_first_frame_outside(tmp_path: Path) -> None:
    body = "".join(f'  <frame name="f{i}" parent="{f"f{i - 1}" if i else "world"}" xyz="60 0 0"/>\n' for i in range(4))
    path, text = cell_file(tmp_path, body)
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, '<frame name="f1"', "frame 'f1' is at (120, 0, 0) m in the world, outside ±100 m, "
           "the bound of a length in a cell (its xyz adds to those of the frames above it)"),
    ]


def test_joint_pose_values_are_bounded_angles(tmp_path: Path) -> None:
    path, text = cell_file(tmp_path, '  <joint_pose name="p" group="arm" unit="deg" joints="0 1e308 0 0 0 0"/>\n')
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'joints="', "joint pose 'p': joint 2 = 1e+308 deg is outside ±720 deg, the bound of an angle (two turns)"),
    ]


def test_a_free_attribute_that_is_a_number_must_be_finite(tmp_path: Path) -> None:
    body = '  <element name="r" kind="rivet" diameter="1e999" note="inf"/>\n'
    path, text = cell_file(tmp_path, body)
    assert [str(d) for d in validate_cell(path)] == [
        at(path, text, 'diameter=', "attribute diameter='1e999' of <element> 'r' is not a finite number"),
    ]  # "inf" is a word here, kept as text


def test_a_cell_within_the_bounds_loads(tmp_path: Path) -> None:
    body = '  <frame name="edge" xyz="100 -100 100" rpy="720 -720 0"/>\n'
    path, _ = cell_file(tmp_path, body, ' angle_unit="deg"')
    assert validate_cell(path) == []
    assert load_cell(path).pose("edge").position == pytest.approx((100.0, -100.0, 100.0))


# ------------------------------------------------------------------------------ the application
def replace_param(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize(
    ("target", "needle", "message"),
    [
        ("1e308,0,0,0,0,0", 'value="1e308', "param 1 (target) of move_to: x = 1e+308 m is outside ±100 m, the bound of a length in a cell"),
        ("0.4 0 0.05 1e308 0 0", 'value="0.4', "param 1 (target) of move_to: roll = 1e+308 rad is outside ±12.5664 rad, the bound of an angle (two turns)"),
        ("450mm 0 1e9mm 180deg 0 0", 'value="450mm', "param 1 (target) of move_to: z = 1e+09 mm is outside ±100000 mm, the bound of a length in a cell"),
        ("0.4 0 0.05 180deg 0 1e308deg", 'value="0.4', "param 1 (target) of move_to: yaw = 1e+308 deg is outside ±720 deg, the bound of an angle (two turns)"),
    ],
)
def test_inline_targets_are_bounded_at_their_param(work: Path, target: str, needle: str, message: str) -> None:
    text = replace_param(APP_XML, '<param value="drill_2"/>', f'<param value="{target}"/>')
    path = work / "app.xml"
    path.write_text(text)
    assert [str(d) for d in validate_application(path, CATALOG)] == [at(path, text, needle, message)]


def test_a_number_param_without_its_own_maximum_is_held_to_its_family_bound(work: Path) -> None:
    text = replace_param(APP_XML, '<torso_head><function name="wait"></function></torso_head>',
                         '<torso_head><function name="sleep"><params><param value="1e308"/></params></function></torso_head>')
    path = work / "app.xml"
    path.write_text(text)
    assert [str(d) for d in validate_application(path, CATALOG)] == [
        at(path, text, 'value="1e308', "param 1 (duration) of sleep: duration = 1e+308 s is outside [0, 86400] s, the bound of a duration (one day)"),
    ]


def test_an_alarm_timeout_of_a_century_is_refused(work: Path) -> None:
    century = "3" + "0" * 9  # a plain decimal, as the schema wants: 95 years
    text = replace_param(APP_XML, 'alarm_timeout="0"', f'alarm_timeout="{century}"')
    path = work / "app.xml"
    path.write_text(text)
    assert [str(d) for d in validate_application(path, CATALOG)] == [
        at(path, text, "alarm_timeout=", "<error_policy> alarm_timeout = 3e+09 s is outside [0, 86400] s, the bound of a duration (one day)"),
    ]


def test_the_catalog_refuses_what_validation_refuses() -> None:
    """The group machine binds with the same catalog: a run never gets the unbounded target."""
    spec = CATALOG.get("move_to")
    assert spec is not None
    with pytest.raises(ValueError, match=r"x = 1e\+308 m is outside ±100 m"):
        spec.bind(["1e308,0,0,0,0,0"], BindContext(NEXTAGE_OPEN, "left_arm"))


# ------------------------------------------------------------------------------ one table
def test_one_table_bounds_the_cell_reader_the_application_reader_and_the_catalog(work: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Tighten the table and every reader follows: no copy of a bound anywhere."""
    cell = work / "cells" / "far_cell.xml"
    cell.write_text(CELL_XML.replace('xyz="0.45 0.0 0.05"', 'xyz="2 0.0 0.05"'))
    text = replace_param(APP_XML, '<param value="drill_2"/>', '<param value="3,0,0,0,0,0"/>')
    text = replace_param(text, 'alarm_timeout="0"', 'alarm_timeout="120"')
    path = _written(work, text)
    assert validate_cell(cell) == [] and validate_application(path, CATALOG) == []
    monkeypatch.setitem(limits.BY_UNIT, "m", limits.Bound(-1.0, 1.0, "m", "a test bound"))
    monkeypatch.setitem(limits.BY_UNIT, "s", limits.Bound(0.0, 60.0, "s", "a test bound"))
    assert [d.message for d in validate_cell(cell)] == ["xyz of <frame> 'part': x = 2 m is outside ±1 m, a test bound"]  # the cell reader
    assert [d.message for d in validate_application(path, CATALOG)] == [
        "<error_policy> alarm_timeout = 120 s is outside [0, 60] s, a test bound",  # the application reader
        "param 1 (target) of move_to: x = 3 m is outside ±1 m, a test bound",  # the catalog
    ]


def test_the_schema_counts_retries_with_the_table() -> None:
    text = (Path(__file__).resolve().parents[1] / "apps_xml" / "schema" / "application.xsd").read_text()
    count = re.search(r'<xs:simpleType name="count">.*?<xs:maxInclusive value="(\d+)"/>', text, re.S)
    assert count is not None and int(count.group(1)) == limits.MAX_RETRIES


def test_the_bounds_are_what_the_guide_says() -> None:
    guide = (Path(__file__).resolve().parents[1] / "docs" / "application_xml.md").read_text()
    for quantity, bound, _ in limits.table():
        assert f"| {quantity} | {bound} |" in guide, (quantity, bound)


def test_bounds_describe_themselves() -> None:
    assert limits.LENGTH.describe() == "±100 m"
    assert limits.ANGLE.describe(math.pi / 180.0, "deg") == "±720 deg"
    assert limits.FRACTION.violation("speed", 150.0, 0.01, "%") == "speed = 150 % is outside [0, 100] %, the bound of a fraction (0 to 1, i.e. 0 % to 100 %)"
    assert limits.DURATION.violation("t", 10.0) is None
    assert limits.LENGTH.violation("x", math.nan) is not None


def test_a_loaded_application_is_within_the_bounds(work: Path) -> None:
    application = load_application(_written(work, APP_XML), CATALOG)
    assert application.cell is not None
    for name in application.cell.frames:
        assert all(abs(v) <= limits.LENGTH.upper for v in application.cell.pose(name).position)


def _written(work: Path, text: str) -> Path:
    path = work / "app.xml"
    path.write_text(text)
    return path
