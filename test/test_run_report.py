"""``report RUN.mcap|TRACE.jsonl``: the run summary and the Fig. 12 timeline, from either record, whole or cut."""
from __future__ import annotations

import io
from pathlib import Path

import pytest
from lxml import etree

from cell_runner.cli import main

RIVET = "apps_xml/rivet_installation.xml"


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("report")
    record, trace = folder / "run.mcap", folder / "run.jsonl"
    err = io.StringIO()
    assert main(["run", RIVET, "--speed", "max", "-q", "--record", str(record), "--trace", str(trace)], io.StringIO(), err) == 0, err.getvalue()
    return record, trace


def report(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(["report", *argv], out, err)
    return code, out.getvalue(), err.getvalue()


def _groups(text: str) -> dict[str, str]:
    return {line.split()[0]: line for line in text.splitlines() if " busy " in line}


def test_a_recording_and_a_trace_give_the_same_summary(records: tuple[Path, Path], tmp_path: Path) -> None:
    record, trace = records
    code, from_record, _ = report(str(record), "--timeline", str(tmp_path / "t.svg"))
    assert code == 0
    assert "ran: rivet_installation (apps_xml/rivet_installation.xml) on nextage_open via nextage-sim" in from_record
    assert "operations: 10 started, 10 complete" in from_record and "CUT" not in from_record
    code, from_trace, _ = report(str(trace), "--no-timeline")
    assert code == 0 and "CUT" not in from_trace
    assert _groups(from_record) == _groups(from_trace) and set(_groups(from_trace)) == {"left_arm", "right_arm", "torso_head"}
    assert from_record.count("vision: ") == 8  # four holes, located by each arm
    svg = etree.parse(str(tmp_path / "t.svg"))
    assert svg.getroot().tag.endswith("svg")
    text = " ".join(svg.getroot().itertext())
    assert "left_arm" in text and "debur_drilling" in text and "op 10" in text


def test_a_cut_record_says_so_and_keeps_what_it_has(records: tuple[Path, Path], tmp_path: Path) -> None:
    record, trace = records
    data = record.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 6 // 10])
    code, text, _ = report(str(cut), "--timeline", str(tmp_path / "cut.png"))
    assert code == 0 and "CUT: the recording has no end" in text
    assert "operations:" in text and (tmp_path / "cut.png").read_bytes()[:4] == b"\x89PNG"
    lines = trace.read_text().splitlines(keepends=True)
    cut_trace = tmp_path / "cut.jsonl"
    cut_trace.write_text("".join(lines[: len(lines) // 2]))
    code, text, _ = report(str(cut_trace), "--no-timeline")
    assert code == 0 and "CUT: no run_end record" in text


def test_a_missing_file_is_one_line(tmp_path: Path) -> None:
    code, out, err = report(str(tmp_path / "nope.mcap"))
    assert code == 1 and err.strip().count("\n") == 0 and "no such file" in err
