"""bench/all.py's table and its generated section of docs/benchmarks.md, from given summaries.

No timing here (the benches measure; a test only checks how their summaries become rows): a figure is
read from its bench's JSON, met or not against its aim, and a bench that failed, timed out, was not run
or left a figure out shows that figure as "not measured" with why -- never an empty or stale cell.  The
markdown section is replaced where it stands, never added twice, and the rest of the document is kept.
"""
from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]


def load_all() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_all", ROOT / "bench" / "all.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_all"] = module
    spec.loader.exec_module(module)
    return module


ALL = load_all()
FIGURES = sys.modules["figures"]

VPLUS = {"raw_echo_rtt_us": 19.9, "client_rtt_us": 27.8, "client_vs_echo_ratio": 1.397, "client_vs_echo_ratio_median": 1.361,
         "raw_echo_cpu_us": 20.8, "client_cpu_us": 28.0, "client_vs_echo_cpu_ratio_median": 1.359, "client_vs_echo_cpu_ratio_range": [1.261, 1.549],
         "client_simulator_rtt_us": 75.1, "joined_acks_per_s": 46304, "rounds": 1000, "joined_messages": 5000, "repeats": 5}
PRIMITIVE = {"function_cpu_us": 161.93, "skill_cpu_us": 77.6, "py_trees_version": "2.6.0", "py_trees_tick_cpu_us": 8.05,
             "function_vs_tick": 19.97, "function_vs_tick_range": [17.72, 21.08], "skill_vs_tick": 3.9, "skill_vs_tick_range": [3.5, 4.1], "aim_ticks": 4.35}


def rows_of(bench: object, outcome: object) -> list[object]:
    return ALL.build_rows([bench], [outcome], suite=False)


def test_figures_are_read_from_the_summary_and_met_follows_the_aim() -> None:
    function, skill = rows_of(FIGURES.PRIMITIVE, ALL.Outcome("primitive_overhead", 5.0, PRIMITIVE, exit=0))
    assert function.met == "**no**" and function.ratio == "20.0x" and "161.9 us CPU" in function.figure and "8.05 us" in function.baseline
    assert skill.met == "yes" and skill.ratio == "3.90x"
    assert [ALL.ratio_text(r) for r in (0.1049, 1.359, 23.94)] == ["0.105x", "1.36x", "23.9x"]
    round_trip, joined = rows_of(FIGURES.VPLUS, ALL.Outcome("vplus_client", 4.0, VPLUS, exit=0))
    assert round_trip.met == "**no**" and round_trip.ratio == "1.36x"  # 1.359 against <= 1.3
    assert joined.met == "yes" and joined.figure == "46,304 acked messages/s"


def test_a_bench_that_failed_shows_every_figure_of_it_as_not_measured_with_why() -> None:
    failed = ALL.Outcome("vplus_client", 3.0, reason="exit 1, no JSON summary: ConnectionRefusedError: [Errno 111]", exit=1)
    rows = rows_of(FIGURES.VPLUS, failed)
    assert len(rows) == len(FIGURES.VPLUS.figures) == 2
    for row in rows:
        assert row.met == "not measured: exit 1, no JSON summary: ConnectionRefusedError: [Errno 111]"
        assert (row.figure, row.baseline, row.ratio) == ("-", "-", "-")
    timed_out = rows_of(FIGURES.VPLUS, ALL.Outcome("vplus_client", 120.0, reason="timed out after 120 s"))
    assert {row.met for row in timed_out} == {"not measured: timed out after 120 s"}


def test_a_figure_missing_from_the_summary_is_named_and_the_others_still_read() -> None:
    summary = {k: v for k, v in VPLUS.items() if k != "joined_acks_per_s"}
    round_trip, joined = rows_of(FIGURES.VPLUS, ALL.Outcome("vplus_client", 4.0, summary, exit=0))
    assert round_trip.met == "**no**"
    assert joined.met == "not measured: vplus_client's summary has no 'joined_acks_per_s'"
    no_peer = {**PRIMITIVE, "py_trees_tick_cpu_us": None}
    rows = rows_of(FIGURES.PRIMITIVE, ALL.Outcome("primitive_overhead", 5.0, no_peer, exit=0))
    assert all(row.met.startswith("not measured: py_trees is not installed") for row in rows)
    short = rows_of(FIGURES.DRY_RUN, ALL.Outcome("dry_run", 9.0, {"rows": []}, exit=0))
    assert all(row.met.startswith("not measured: dry_run's summary is short of a row") for row in short)


def test_a_bench_left_out_and_the_test_suite_are_not_measured_with_their_reason() -> None:
    rows = ALL.build_rows([FIGURES.VPLUS, FIGURES.RSI], [ALL.Outcome("vplus_client", 4.0, VPLUS, exit=0)])
    rsi = [r for r in rows if r.path.startswith("KUKA RSI") or r.path.startswith("RSI")]
    assert rsi and all(r.met == "not measured: not run (left out by --only or --issue-only)" for r in rsi)
    assert rows[-1].path.startswith("the test suite") and rows[-1].met.startswith("not measured: timed by pytest")


def test_the_summary_is_the_last_json_line_and_a_failure_says_its_last_words(tmp_path: Path) -> None:
    ok = ALL.run("ok", [sys.executable, "-c", "print('human text'); print('{\"figure\": 1.5}')"], 60)
    assert ok.summary == {"figure": 1.5} and ok.exit == 0
    bad = ALL.run("bad", [sys.executable, "-c", "import sys; print('{\"early\": 1}'); print('no json'); sys.exit('the bench broke: port in use')"], 60)
    assert bad.summary is None and bad.reason == "exit 1, no JSON summary: the bench broke: port in use"
    assert ALL.last_json("[1, 2]\n") is None and ALL.last_json("\n\n") is None


def test_a_bench_out_of_time_is_ended_with_the_processes_it_started(tmp_path: Path) -> None:
    pid_file = tmp_path / "grandchild.pid"
    script = (f"import subprocess, sys, time\np = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
              f"open({str(pid_file)!r}, 'w').write(str(p.pid))\ntime.sleep(120)\n")
    outcome = ALL.run("slow", [sys.executable, "-c", script], 3)
    assert outcome.summary is None and outcome.reason == "timed out after 3 s"
    status = Path(f"/proc/{int(pid_file.read_text())}/stat")

    def gone() -> bool:  # or a zombie awaiting its reaper: a signal's delivery takes a moment to end a process
        try:
            return status.read_text().rsplit(")", 1)[1].split()[0] == "Z"
        except (FileNotFoundError, ProcessLookupError):
            return True
    deadline = time.monotonic() + 10.0
    while not gone() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert gone()


def test_a_missing_install_or_a_spent_budget_starts_nothing() -> None:
    never = FIGURES.Bench("no_such_bench.py", (), 60, FIGURES.VPLUS.figures, needs="no_such_module_for_bench_all")
    spent = FIGURES.Bench("no_such_bench_either.py", (), 60, FIGURES.VPLUS.figures)
    said: list[str] = []
    first, second = ALL.run_all([never, spent], 0.0, lambda text, **_: said.append(text))
    assert first.reason == "needs no_such_module_for_bench_all, which is not installed here"
    assert second.reason == "the budget of 0 s was spent before it"
    assert all("..." not in line for line in said)  # nothing was started


DOC = "# Benchmarks\n\nIntro.\n\n## First section\n\nKept | as it is.\n\n## Second\n\nAlso kept.\n"


def test_the_generated_section_goes_in_before_the_first_section_then_is_replaced_in_place() -> None:
    first = ALL.replace_section(DOC, f"{ALL.BEGIN}\nTABLE ONE\n{ALL.END}")
    assert first.index("TABLE ONE") < first.index("## First section") and first.startswith("# Benchmarks\n\nIntro.\n\n" + ALL.BEGIN)
    second = ALL.replace_section(first, f"{ALL.BEGIN}\nTABLE TWO\n{ALL.END}")
    assert second.count(ALL.BEGIN) == 1 and second.count(ALL.END) == 1
    assert "TABLE ONE" not in second and "TABLE TWO" in second
    assert second.replace(f"{ALL.BEGIN}\nTABLE TWO\n{ALL.END}\n\n", "") == DOC
    with pytest.raises(ValueError, match="markers"):
        ALL.replace_section(DOC + ALL.BEGIN, "x")


def saved(tmp_path: Path) -> Path:
    meta = {"command": "nice .venv/bin/python bench/all.py --markdown docs/benchmarks.md", "date": "2026-11-27 16:55 UTC", "head": "abc1234",
            "cpus": 2, "load_before": 3.2, "load_after": 4.1, "seconds": 512.0, "benches": ["vplus_client", "dds_primitive_overhead"],
            "commands": {"vplus_client": "bench/vplus_client.py --rounds 7"}}
    outcomes = [{"bench": "vplus_client", "seconds": 4.0, "summary": VPLUS, "reason": None, "exit": 0},
                {"bench": "dds_primitive_overhead", "seconds": 240.0, "summary": None, "reason": "timed out after 240 s", "exit": None}]
    path = tmp_path / "summaries.json"
    path.write_text(json.dumps({"meta": meta, "outcomes": outcomes}))
    return path


def test_the_document_is_regenerated_from_saved_summaries_once_however_often(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    doc = tmp_path / "benchmarks.md"
    doc.write_text(DOC)
    source = saved(tmp_path)
    for _ in range(2):
        assert ALL.main(["--from", str(source), "--markdown", str(doc)]) == 0
    text = doc.read_text()
    assert text.count(ALL.BEGIN) == 1 and text.count("| path | figure | baseline | ratio | aim | met |") == 1
    assert "Command: `nice .venv/bin/python bench/all.py --markdown docs/benchmarks.md`, 2026-11-27 16:55 UTC, HEAD abc1234" in text
    assert "load average 3.2 before and 4.1 after" in text
    assert "| `bench/vplus_client.py --rounds 7` | 4 s | summary read |" in text  # the arguments it ran with, not today's
    assert "| `bench/dds_primitive_overhead.py 1000 3` | 240 s | timed out after 240 s |" in text
    assert "| 1.36x | <= 1.3x the echo | **no** |" in text
    assert "DDS, per primitive within a skill, one process per node" in text and "not measured: timed out after 240 s" in text
    assert "Kept \\| as it is." not in text and "Kept | as it is." in text  # only the table's cells are escaped
    assert "V+ round trip, our client" in capsys.readouterr().out


def test_outputs_never_overwrite_each_other_or_the_input(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    doc.write_text(DOC)
    source = saved(tmp_path)
    with pytest.raises(SystemExit, match="different files"):
        ALL.main(["--from", str(source), "--markdown", str(doc), "--save", str(doc)])
    with pytest.raises(SystemExit, match="no such file"):
        ALL.main(["--from", str(source), "--markdown", str(tmp_path / "missing.md")])
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(SystemExit, match="not a file --save wrote"):
        ALL.main(["--from", str(bad), "--markdown", str(doc)])
    assert doc.read_text() == DOC


def slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces to hyphens."""
    return "".join(c for c in heading.strip().lower() if c.isalnum() or c in " -_").replace(" ", "-")


def test_every_row_links_to_a_section_of_the_benchmarks_page() -> None:
    text = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    anchors = {slug(line.lstrip("#")) for line in text.splitlines() if line.startswith("#")}
    figures = [f for bench in FIGURES.ALL for f in bench.figures] + [FIGURES.SUITE]
    assert [f.path for f in figures if f.section not in anchors] == []


def test_every_bench_of_the_folder_is_run_by_all() -> None:
    scripts = {path.name for path in (ROOT / "bench").glob("*.py")} - {"all.py", "figures.py"}
    assert scripts == {bench.script for bench in FIGURES.ALL}
