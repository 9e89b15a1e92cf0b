"""The dry run's verdict, kept: an unchanged application is not checked twice, and a kept verdict is never trusted blindly.

What an integrator relies on: the second ``run`` of an application nothing of which changed starts at once and says
whose verdict holds; any change (the application, its cell, an option, the trajectory database, the program) checks
again; a failed verdict is checked again every time; an entry damaged on the disk is ignored; the run is still
checked from where the robot is measured to be; the cache never writes over a file of the run.
"""
from __future__ import annotations

import io
import json
import os
import shutil
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import cell_runner.dry_run.check as check_module
import cell_runner.dry_run.start as start_module
import cell_runner.dry_run.verdict_cache as cache_module
from app_functions.registry import full_catalog
from cell_runner.cli import main
from cell_runner.dry_run.report import CollisionCheck, DryRunReport, Finding, GroupTime, Span
from cell_runner.dry_run.simulators import setup_for
from cell_runner.dry_run.verdict_cache import BadEntry, Verdict, VerdictCache, cache_dir, decode, encode, verdict_key
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import load_application
from execution_engine.engine.waits import FlagWait
from robot_bridges.backend import BackendOptions

ROOT = Path(__file__).resolve().parents[1]
RIVET_CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
KEY = "ab" * 32
AN_HOUR_AGO = time.time() - 3600

REPORT = DryRunReport(
    app="checked", file="/cell/app.xml", backend="nextage-sim", time_base="simulated clock", findings=(),
    timeline=(Span("left_arm", ("left_arm",), "1", "move_to_joint_pose", "move to initial", 0.0, 1.5),
              Span("right_arm", ("left_arm", "right_arm"), "2", "dual", "dual move", 1.5, 2.25)),
    cycle_time=2.25, groups={"left_arm": GroupTime(2.25, 0.0, 2), "right_arm": GroupTime(0.75, 1.5, 1)},
    operations_total=2, operations_checked=2, collisions=CollisionCheck(2, 113, 0.01),
    waits=(FlagWait("right_arm", "2", "hands_left", 0.5, 1.5, "passed", "zone"),),
    start=(("LARM_JOINT0", "RARM_JOINT0"), (0.0, -0.25)), end=(("LARM_JOINT0", "RARM_JOINT0"), (0.1, -0.2)),
)
FINDING = Finding("unreachable", "left_arm", "1", "move_to", "move to far", "no solution", "/cell/app.xml", 3, 5, 0.0)


def cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(args), out, err)
    return code, out.getvalue(), err.getvalue()


def settled(*paths: Path) -> None:
    """Modified an hour ago: files written by the test just now are (rightly) never taken from the cache."""
    for path in paths:
        os.utime(path, (AN_HOUR_AGO, AN_HOUR_AGO))


def small_app(folder: Path, pose: str = "initial", extra: str = "") -> Path:
    """One operation: the left arm to a named joint pose (a dry run of a moment)."""
    cell = folder / "cell.xml"
    shutil.copyfile(RIVET_CELL, cell)
    path = folder / "app.xml"
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<application name="checked" robot="nextage" cell="{cell.name}">\n'
        f'  <operation id="1"><left_arm><function name="move_to_joint_pose"><params><param value="{pose}"/></params></function>'
        f'</left_arm>{extra}</operation>\n</application>\n', encoding="utf-8")
    settled(path, cell)
    return path


def entries() -> list[Path]:
    folder = cache_dir()
    return sorted(folder.glob("*.verdict.json")) if folder.is_dir() else []


# ---------------------------------------------------------------------------------- an entry
def test_a_kept_verdict_reads_back_as_it_was_written() -> None:
    verdict = Verdict(REPORT, 1_790_000_000.5)
    assert decode(encode(verdict, KEY), KEY) == verdict


def test_an_entry_is_the_verdict_of_its_own_key_only() -> None:
    with pytest.raises(BadEntry, match="another key"):
        decode(encode(Verdict(REPORT, 1.0), KEY), "cd" * 32)


def test_a_failed_verdict_is_never_kept_nor_read_as_passed(tmp_path: Path) -> None:
    failed = DryRunReport(**{**REPORT.__dict__, "findings": (FINDING,)})
    cache = VerdictCache(tmp_path)
    assert not cache.put(KEY, Verdict(failed, 1.0))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(BadEntry, match="not a passed verdict"):  # even when written with a valid seal
        decode(encode(Verdict(failed, 1.0), KEY), KEY)
    incomplete = DryRunReport(**{**REPORT.__dict__, "complete": False, "notes": ("stopped for good",)})
    assert not cache.put(KEY, Verdict(incomplete, 1.0))


@given(st.binary(max_size=2000))
def test_any_bytes_are_a_verdict_or_refused_in_one_kind_of_error(data: bytes) -> None:
    try:
        decode(data, KEY)
    except BadEntry:
        pass


GOOD = encode(Verdict(REPORT, 1_790_000_000.0), KEY)


@given(st.integers(0, len(GOOD) - 1), st.integers(1, 255), st.integers(0, len(GOOD)))
@example(GOOD.index(b"2.25"), ord("3") ^ ord("2"), len(GOOD))  # the cycle time 2.25 -> 3.25: a changed figure, not JSON noise
def test_an_entry_damaged_anywhere_is_refused(at: int, flip: int, cut: int) -> None:
    """A byte changed or the end lost, wherever: never a verdict read from it (the seal covers every figure)."""
    damaged = bytearray(GOOD[:cut])
    if at < len(damaged):
        damaged[at] ^= flip
    if bytes(damaged) == GOOD:
        return
    with pytest.raises(BadEntry):
        decode(bytes(damaged), KEY)


@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=4), max_leaves=30))
def test_a_well_sealed_entry_of_any_shape_is_a_report_or_refused(report: Any) -> None:
    """Crafted with a valid seal (the seal is no secret): every field is still checked before a report is built."""
    checked_at = 1.0
    try:
        seal = cache_module.seal(KEY, checked_at, report)  # as the writer would seal it
    except ValueError:  # not a number JSON has: no entry could say it
        return
    data = json.dumps({"format": 1, "key": KEY, "checked_at": checked_at, "seal": seal, "report": report}).encode()
    try:
        decode(data, KEY)
    except BadEntry:
        pass


def test_an_unreadable_entry_is_ignored_and_said(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    cache = VerdictCache(tmp_path)
    cache.path(KEY).write_bytes(b'{"format": 1, "key": "' + KEY.encode() + b'", "checked_at": 1.0, "report": {')
    assert cache.get(KEY) is None
    assert "is not one (not JSON" in caplog.text and "checking again" in caplog.text
    cache.path(KEY).unlink()
    cache.path(KEY).mkdir()  # a folder where the entry should be
    assert cache.get(KEY) is None


def test_writes_are_whole_bounded_and_few(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cache = VerdictCache(tmp_path / "kept")
    assert cache.put(KEY, Verdict(REPORT, 1.0))
    assert [p.name for p in (tmp_path / "kept").iterdir()] == [f"{KEY}.verdict.json"]  # no temporary file left
    assert (tmp_path / "kept" / f"{KEY}.verdict.json").stat().st_mode & 0o077 == 0  # the user's own
    monkeypatch.setattr(cache_module, "MAX_ENTRY_BYTES", 1000)
    assert not cache.put("cd" * 32, Verdict(REPORT, 1.0))  # larger than an entry may be: not kept
    monkeypatch.setattr(cache_module, "MAX_ENTRY_BYTES", 1 << 20)
    for k in range(cache_module.MAX_ENTRIES + 5):
        entry = cache.path(f"{k:064x}")
        assert cache.put(f"{k:064x}", Verdict(REPORT, 1.0))
        os.utime(entry, (1000.0 + k, 1000.0 + k))
    cache.prune()
    kept = sorted(p.name for p in (tmp_path / "kept").iterdir())
    assert len(kept) == cache_module.MAX_ENTRIES and f"{0:064x}.verdict.json" not in kept  # the oldest went


def test_an_entry_is_never_written_over_a_file_of_the_run(tmp_path: Path) -> None:
    cache = VerdictCache(tmp_path)
    trace = cache.path(KEY)
    trace.write_text("the run's trace\n")
    link = tmp_path / "trace.jsonl"
    link.symlink_to(trace)
    assert not cache.put(KEY, Verdict(REPORT, 1.0), avoid=[str(link)])
    assert trace.read_text() == "the run's trace\n"


def test_the_cache_is_per_user_where_xdg_says() -> None:
    assert cache_dir({"XDG_CACHE_HOME": "/srv/cache"}) == Path("/srv/cache/dual_arm_executive/dry_run")
    assert cache_dir({"XDG_CACHE_HOME": "relative"}) == Path.home() / ".cache" / "dual_arm_executive" / "dry_run"
    assert cache_dir({}) == Path.home() / ".cache" / "dual_arm_executive" / "dry_run"


# ------------------------------------------------------------------------------------ the key
def test_the_key_changes_with_everything_the_dry_run_depends_on(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = small_app(tmp_path)
    catalog = full_catalog()

    def key(options: dict[str, str] | None = None, db: str | None = None) -> str:
        app = load_application(path, catalog)
        return verdict_key(app, setup_for("nextage-sim", BackendOptions(robot=NEXTAGE_OPEN, extra=options or {})), db)

    first = key()
    assert key() == first  # nothing changed: the same key
    seen = {first}
    path.write_text(path.read_text().replace('"initial"', '"off"'))
    seen.add(key())  # the application
    cell = tmp_path / "cell.xml"
    cell.write_text(cell.read_text().replace('xyz="0.34 0.0 0.0"', 'xyz="0.35 0.0 0.0"'))
    with_cell = key()
    seen.add(with_cell)  # its cell
    seen.add(key({"initial_pose": "off"}))  # an option of the simulator
    assert key(db=str(tmp_path / "other.sqlite")) == with_cell  # another database, none there either: the same dry run
    (tmp_path / "other.sqlite").write_bytes(b"SQLite format 3\x00" + bytes(100))
    seen.add(key(db=str(tmp_path / "other.sqlite")))  # its content
    program = cache_module.program_digest
    monkeypatch.setattr(cache_module, "program_digest", lambda: "another program")
    seen.add(key())  # the program
    monkeypatch.setattr(cache_module, "program_digest", program)
    elsewhere = tmp_path / "copy"
    elsewhere.mkdir()
    shutil.copyfile(path, elsewhere / "app.xml")
    shutil.copyfile(cell, elsewhere / "cell.xml")
    path = elsewhere / "app.xml"
    seen.add(key())  # the same bytes elsewhere: its report names another file
    assert len(seen) == 7


# ----------------------------------------------------------------------- on the command line
def test_an_unchanged_application_is_checked_once_and_the_console_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = small_app(tmp_path)
    code, out, _ = cli("validate", "--simulate", str(path))
    assert code == 0 and "dry run of checked on nextage-sim: no problems found" in out
    assert len(entries()) == 1

    def never(*_args: Any, **_kwargs: Any) -> Any:
        raise AssertionError("dry-run again although nothing changed")

    monkeypatch.setattr(check_module, "dry_run", never)
    code, out, _ = cli("validate", "--simulate", str(path))
    assert code == 0
    assert out.splitlines()[-1].startswith("dry run: unchanged since the check of ")
    assert out.splitlines()[-1].endswith(" (cached verdict: passed, cycle time %.2f s)" % decode(entries()[0].read_bytes(), entries()[0].name[:64]).report.cycle_time)
    code, out, _ = cli("run", str(path), "--speed", "max", "--trajectory-db", str(tmp_path / "app.trajectories.sqlite"))
    assert code == 0 and out.startswith("dry run: unchanged since the check of ")  # run takes the verdict validate kept


def test_a_changed_application_is_checked_again(tmp_path: Path) -> None:
    path = small_app(tmp_path)
    assert cli("validate", "--simulate", str(path))[0] == 0
    path.write_text(path.read_text().replace('"initial"', '"off"'))
    settled(path)
    code, out, _ = cli("validate", "--simulate", str(path))
    assert code == 0 and "dry run of checked on nextage-sim" in out and "unchanged" not in out
    assert len(entries()) == 2


def test_a_file_changed_just_before_it_was_read_is_neither_taken_nor_kept(tmp_path: Path) -> None:
    path = small_app(tmp_path)
    path.touch()  # modified now: it may have changed while it was read
    assert cli("validate", "--simulate", str(path))[0] == 0
    assert entries() == []


def test_a_failed_verdict_is_checked_every_time(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    far = '<right_arm><function name="move_to"><params><param value="1.2,0.3,0.2,180deg,0,0"/></params></function></right_arm>'
    path = small_app(tmp_path, extra=far)
    runs = []
    real = check_module.dry_run
    monkeypatch.setattr(check_module, "dry_run", lambda *a, **k: runs.append(1) or real(*a, **k))
    for _ in range(2):
        code, _, err = cli("validate", "--simulate", str(path))
        assert code == 1 and "unreachable" in err
    assert len(runs) == 2 and entries() == []


def test_a_kept_verdict_is_only_the_first_check_the_run_checks_from_where_the_robot_is(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A kept verdict says where its dry run started; a robot found elsewhere is dry-run again from there."""
    path = small_app(tmp_path)
    assert cli("validate", "--simulate", str(path))[0] == 0
    entry = entries()[0]
    kept = decode(entry.read_bytes(), entry.name[:64])
    assert kept.report.start is not None
    names, positions = kept.report.start
    elsewhere = DryRunReport(**{**kept.report.__dict__, "start": (names, tuple(p + 0.2 for p in positions))})
    entry.write_bytes(encode(Verdict(elsewhere, kept.checked_at), entry.name[:64]))  # as if the simulator had started elsewhere
    froms = []
    real = start_module.dry_run_setup
    monkeypatch.setattr(start_module, "dry_run_setup", lambda app, setup, db=None, start=None: froms.append(start) or real(app, setup, db, start))
    code, out, err = cli("run", str(path), "--speed", "max", "--trajectory-db", str(tmp_path / "app.trajectories.sqlite"))
    assert out.startswith("dry run: unchanged since the check of ")
    assert froms and froms[0] is not None  # dry-run again, from the measured joints
    assert "the robot is not where checked starts" in out + err
    assert code in (0, 1)
