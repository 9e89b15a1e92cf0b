"""Every bench of issue 22's table (and the others that run here), one after the other, in one table.

Usage: nice .venv/bin/python bench/all.py [--budget 600] [--only NAME ...] [--issue-only]
                                          [--markdown docs/benchmarks.md] [--save FILE] [--from FILE]

Each bench runs in a process of its own (its own session, so a bench that starts node processes is
ended whole), with the short arguments of bench/figures.py and a bound on its wall time; the whole
set shares ``--budget`` seconds (ten minutes by default), and a bench the budget no longer covers is
not started.  What a bench measured is read from the JSON object it prints as its last line, never
from its human text.  The table: path, figure, baseline (measured side by side in the same run),
ratio (figure / baseline), aim, met -- or "not measured" with why (the bench failed, timed out, is
missing an optional install, or its summary lacks the figure).

``--markdown FILE`` writes the table, with the command, the date, HEAD and the load average, between
the generated-section markers of FILE (docs/benchmarks.md), replacing what was there; the rest of the
file is left as it is.  ``--save FILE`` keeps every summary (JSON); ``--from FILE`` builds the table
from such a file without running anything.  Benches share two cores with whatever else runs: start
this with ``nice``, and read the ratios, which each bench takes side by side, rather than the times.
"""
from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from figures import ALL, ISSUE, SUITE, Bench, Figure  # noqa: E402

BEGIN = "<!-- bench/all.py: begin (generated: edit bench/all.py or bench/figures.py, not this section) -->"
END = "<!-- bench/all.py: end -->"
MINIMUM = 20.0  # seconds: a bench the budget covers for less than this is not started
GRACE = 5.0  # seconds between SIGTERM and SIGKILL of a bench that ran out of time


@dataclass(frozen=True)
class Outcome:
    """What became of one bench: its summary, or why there is none."""

    bench: str
    seconds: float
    summary: dict[str, Any] | None = None
    reason: str | None = None  # set when summary is None
    exit: int | None = None


@dataclass(frozen=True)
class Row:
    path: str
    figure: str
    baseline: str
    ratio: str
    aim: str
    met: str
    section: str = ""


# ------------------------------------------------------------------------------------------- running
def last_json(stdout: str) -> dict[str, Any] | None:
    """The JSON object a bench prints as its last (non-empty) line, or None."""
    lines = [line for line in stdout.splitlines() if line.strip()]
    if not lines:
        return None
    try:
        value = json.loads(lines[-1])
    except ValueError:
        return None
    return value if isinstance(value, dict) else None


def last_words(text: str, limit: int = 160) -> str:
    """The last non-empty line of ``text``, shortened: what a failing bench said last."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    if not lines:
        return "nothing on stderr"
    line = lines[-1]
    return line if len(line) <= limit else line[: limit - 3] + "..."


def run(name: str, argv: Sequence[str], timeout: float) -> Outcome:
    """``argv`` in a session of its own, at most ``timeout`` s; its summary or why there is none."""
    start = time.monotonic()
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        child = subprocess.Popen(argv, cwd=ROOT, stdout=out, stderr=err, stdin=subprocess.DEVNULL, text=True, start_new_session=True)
        try:
            code: int | None = child.wait(timeout)
        except subprocess.TimeoutExpired:
            code = None
            end_session(child, GRACE)
        except BaseException:  # interrupted (Ctrl-C, SIGTERM): its own session does not get the signal, so end it here
            end_session(child, 1.0)
            raise
        seconds = time.monotonic() - start
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if code is None:
        return Outcome(name, seconds, reason=f"timed out after {timeout:.0f} s")
    summary = last_json(stdout)
    if summary is None:
        return Outcome(name, seconds, reason=f"exit {code}, no JSON summary: {last_words(stderr or stdout)}", exit=code)
    return Outcome(name, seconds, summary, exit=code)


def end_session(child: subprocess.Popen[str], grace: float) -> None:
    """Stop a bench and every process it started (its session, by its id): SIGTERM, SIGKILL after ``grace`` s."""
    for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, grace)):
        try:
            os.killpg(child.pid, sig)
        except ProcessLookupError:
            return
        try:
            child.wait(wait)
            return
        except subprocess.TimeoutExpired:
            continue


def interrupted(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def missing(module: str | None) -> bool:
    return module is not None and importlib.util.find_spec(module) is None


def run_all(benches: Iterable[Bench], budget: float, say: Callable[..., None] = print) -> list[Outcome]:
    """Every bench in turn within ``budget`` seconds in all."""
    outcomes = []
    deadline = time.monotonic() + budget
    for bench in benches:
        left = deadline - time.monotonic()
        if missing(bench.needs):
            outcome = Outcome(bench.name, 0.0, reason=f"needs {bench.needs}, which is not installed here")
        elif left < MINIMUM:
            outcome = Outcome(bench.name, 0.0, reason=f"the budget of {budget:.0f} s was spent before it")
        else:
            say(f"{bench.command()} (at most {min(bench.timeout, left):.0f} s) ...", flush=True)
            outcome = run(bench.name, [sys.executable, str(HERE / bench.script), *bench.args], min(bench.timeout, left))
        say(f"  {bench.name}: {outcome.seconds:.0f} s, " + ("summary read" if outcome.summary is not None else f"not measured: {outcome.reason}"), flush=True)
        outcomes.append(outcome)
    return outcomes


# -------------------------------------------------------------------------------------------- the table
def row(figure: Figure, outcome: Outcome | None) -> Row:
    """One figure as a row: read from its bench's summary, or "not measured" and why."""
    def absent(why: str) -> Row:
        return Row(figure.path, "-", "-", "-", figure.aim, f"not measured: {why}", figure.section)

    if outcome is None:
        return absent("not run (left out by --only or --issue-only)")
    if outcome.summary is None:
        return absent(outcome.reason or "no summary")
    try:
        m = figure.read(outcome.summary)
    except KeyError as error:
        return absent(f"{outcome.bench}'s summary has no {error}")
    except LookupError as error:  # IndexError, or a reader's own reason
        return absent(str(error) if type(error) is LookupError else f"{outcome.bench}'s summary is short of a row ({error})")
    except (TypeError, ValueError, ZeroDivisionError) as error:
        return absent(f"{outcome.bench}'s summary has an unusable figure ({error})")
    met = "-" if m.met is None else ("yes" if m.met else "**no**")
    ratio = "-" if m.ratio is None else ratio_text(m.ratio)
    return Row(figure.path, m.figure, m.baseline, ratio, figure.aim, met, figure.section)


def ratio_text(ratio: float) -> str:
    """Three figures where they mean something: 0.105x, 1.44x, 23.9x."""
    return f"{ratio:.3f}x" if ratio < 1 else f"{ratio:.2f}x" if ratio < 10 else f"{ratio:.1f}x"


def build_rows(benches: Iterable[Bench], outcomes: Iterable[Outcome], suite: bool = True) -> list[Row]:
    by_name = {o.bench: o for o in outcomes}
    rows = [row(figure, by_name.get(bench.name)) for bench in benches for figure in bench.figures]
    if suite:
        rows.append(row(SUITE, Outcome("pytest", 0.0, summary={})))
    return rows


def text_table(rows: Sequence[Row]) -> str:
    """The table for a terminal: a line per row, the path padded so the figures line up."""
    width = max(len(r.path) for r in rows)
    lines = [f"{'path':<{width}} | figure | baseline | ratio | aim | met"]
    for r in rows:
        lines.append(f"{r.path:<{width}} | {r.figure} | {r.baseline} | {r.ratio} | {r.aim} | {r.met.replace('**', '')}")
    return "\n".join(lines)


def cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table(rows: Sequence[Row]) -> str:
    lines = ["| path | figure | baseline | ratio | aim | met |", "|---|---|---|---:|---|---|"]
    for r in rows:
        path = f"[{cell(r.path)}](#{r.section})" if r.section else cell(r.path)
        lines.append(f"| {path} | {cell(r.figure)} | {cell(r.baseline)} | {r.ratio} | {cell(r.aim)} | {cell(r.met)} |")
    return "\n".join(lines)


def markdown_section(rows: Sequence[Row], outcomes: Sequence[Outcome], meta: dict[str, Any]) -> str:
    """The generated section: how it was measured, the table, and each bench's command and time."""
    by_name = {o.bench: o for o in outcomes}
    runs = []
    for bench in meta_benches(meta):
        o = by_name.get(bench.name)
        seconds, outcome = ("-", "not run") if o is None else (f"{o.seconds:.0f} s", "summary read" if o.summary is not None else cell(o.reason or ""))
        command = meta.get("commands", {}).get(bench.name, bench.command())  # as it ran (--from: maybe an older figures.py)
        runs.append(f"| `{command}` | {seconds} | {outcome} |")
    return "\n".join([
        BEGIN,
        "## Every aim at a glance (issue 22's table, re-measured)",
        "",
        f"Command: `{meta['command']}`, {meta['date']}, HEAD {meta['head']}, on {meta['cpus']} cores, load average "
        f"{meta['load_before']:.1f} before and {meta['load_after']:.1f} after, {meta['seconds']:.0f} s in all. Each bench ran in its "
        "own process with the short arguments below; each ratio is figure / baseline, both measured side by side in the same "
        "run (interleaved, repeated, medians: the bench's own docstring says how). On a shared machine CPU time is the figure "
        "to read, and the load average above says how shared it was. Each path links to its section below: the history of "
        "the figure and the cause of what is left.",
        "",
        markdown_table(rows),
        "",
        "| bench (short arguments) | wall time | outcome |",
        "|---|---:|---|",
        *runs,
        END,
    ])


def meta_benches(meta: dict[str, Any]) -> list[Bench]:
    names = set(meta.get("benches", []))
    return [b for b in ALL if b.name in names]


def replace_section(document: str, section: str) -> str:
    """``document`` with its generated section replaced by ``section``; without one, ``section`` goes in
    before the first second-level heading (after the title and its introduction)."""
    begin, end = document.find(BEGIN), document.find(END)
    if begin != -1 and end != -1 and end > begin:
        return document[:begin] + section + document[end + len(END):]
    if begin != -1 or end != -1:
        raise ValueError(f"one of the generated-section markers is missing or they are out of order: {BEGIN!r} ... {END!r}")
    at = document.find("\n## ")
    if at == -1:
        return document.rstrip("\n") + "\n\n" + section + "\n"
    return document[: at + 1] + section + "\n\n" + document[at + 1:]


def write_markdown(path: Path, section: str) -> None:
    """Replace the generated section of ``path`` in one step (a temporary file renamed over it)."""
    text = replace_section(path.read_text(encoding="utf-8"), section)
    with tempfile.NamedTemporaryFile("w", encoding="utf-8", dir=path.parent, prefix=f".{path.name}.", delete=False) as tmp:
        tmp.write(text)
    os.replace(tmp.name, path)


# ---------------------------------------------------------------------------------------- the command
def head() -> str:
    """HEAD's short hash, and whether the tree differs from it (the benches ran on the tree)."""
    def git(*args: str) -> str:
        done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False)
        return done.stdout.strip() if done.returncode == 0 else ""
    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    changed = git("status", "--porcelain", "--untracked-files=no")
    return commit + (" (with uncommitted changes in the tree)" if changed else "")


def select(only: Sequence[str] | None, issue_only: bool) -> list[Bench]:
    benches = list(ISSUE if issue_only else ALL)
    if only:
        known = {b.name for b in ALL}
        unknown = sorted(set(only) - known)
        if unknown:
            raise SystemExit(f"bench/all.py: --only: no bench named {', '.join(unknown)} (known: {', '.join(sorted(known))})")
        benches = [b for b in benches if b.name in only]
    return benches


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=600.0, help="seconds for every bench together (default 600)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="only these benches (names without .py)")
    parser.add_argument("--issue-only", action="store_true", help="only the benches of issue 22's table")
    parser.add_argument("--markdown", type=Path, metavar="FILE", help="write the table into FILE's generated section")
    parser.add_argument("--save", type=Path, metavar="FILE", help="keep every bench's summary and the run's details (JSON)")
    parser.add_argument("--from", dest="source", type=Path, metavar="FILE", help="build the table from a --save file, running nothing")
    args = parser.parse_args(argv)
    if not args.budget > 0:
        raise SystemExit(f"bench/all.py: --budget {args.budget:g}: give the seconds the benches may take together (> 0)")
    if args.markdown is not None and not args.markdown.is_file():
        raise SystemExit(f"bench/all.py: --markdown {args.markdown}: no such file")
    outputs = [p.resolve() for p in (args.markdown, args.save) if p is not None]
    if len(set(outputs)) < len(outputs) or (args.source is not None and args.source.resolve() in outputs):
        raise SystemExit("bench/all.py: --markdown, --save and --from must name different files")
    if args.source is not None:
        try:
            saved = json.loads(args.source.read_text(encoding="utf-8"))
            meta, outcomes = saved["meta"], [Outcome(**o) for o in saved["outcomes"]]
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise SystemExit(f"bench/all.py: --from {args.source}: not a file --save wrote ({error})") from None
        benches = meta_benches(meta)
    else:
        benches = select(args.only, args.issue_only)
        words = list(sys.argv[1:] if argv is None else argv)
        if "--save" in words:  # where the summaries were kept is no part of how they were measured
            at = words.index("--save")
            del words[at:at + 2]
        meta = {"command": "nice .venv/bin/python " + " ".join(["bench/all.py", *words]),
                "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "head": head(),
                "cpus": os.cpu_count(), "load_before": os.getloadavg()[0], "benches": [b.name for b in benches],
                "commands": {b.name: b.command() for b in benches}}
        started = time.monotonic()
        signal.signal(signal.SIGTERM, interrupted)  # a stop ends the running bench's session too (see run)
        try:
            outcomes = run_all(benches, args.budget)
        except KeyboardInterrupt:
            print("bench/all.py: stopped; the running bench and what it started were ended", file=sys.stderr)
            return 130
        meta.update(load_after=os.getloadavg()[0], seconds=time.monotonic() - started)
        if args.save is not None:
            args.save.write_text(json.dumps({"meta": meta, "outcomes": [asdict(o) for o in outcomes]}, indent=1) + "\n", encoding="utf-8")
    rows = build_rows(benches, outcomes)
    print()
    print(text_table(rows))
    if args.markdown is not None:
        write_markdown(args.markdown, markdown_section(rows, outcomes, meta))
        print(f"\nwrote the table into {args.markdown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
