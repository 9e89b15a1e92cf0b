"""Every fault and bad option of docs/faults.md, row by row: its one-line message, its exit code, no traceback.

The table in docs/faults.md is the single source: this module reads it, so a row cannot be
documented and untested, nor a message changed without the doc.  Each row's command runs
in-process (``main([...])`` on a worker thread, joined with the row's bound) or, where the
process itself matters, as ``python -m execution_engine`` with the bound as its timeout.  Peers
are loopback: a closed port, a server that never answers, a V+ simulator whose only client slot
is taken, a UDP port no controller sends to.  Runs use simulated time (``--speed max``) except
where the back end needs the robot's real clock (a controller named by ``--host``, KUKA RSI).
"""
from __future__ import annotations

import io
import json
import logging
import os
import re
import shlex
import socket
import struct
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zstandard
from branch_files import BRANCH_FILES
from breakpoint_files import BREAKPOINT_FILES
from paused_edit_files import PAUSED_EDIT_FILES
from dds_domain import domain_env, stop_group
from mixed_cell_files import MIXED_FILES
from cell_group_names_files import NAMED_FILES
from roles_files import ROLE_FILES, ROLE_MODES

from execution_engine.trace_report import read_trace
from operator_station.program import main

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "faults.md"
PREFIX = ["python", "-m", "execution_engine"]
RIVET = (ROOT / "apps_xml" / "rivet_installation.xml").read_text()
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"


def app(body: str, head: str = "", robot: str = "nextage", cell: str | None = None) -> str:
    cell_attr = "" if cell == "" else f' cell="{cell if cell is not None else CELL}"'
    return f'<?xml version="1.0"?>\n<application name="t" robot="{robot}"{cell_attr}>\n{head}{body}</application>\n'


def op(group: str, function: str, *params: str, op_id: str = "1") -> str:
    inner = "".join(f'<param value="{p}"/>' for p in params)
    return f'  <operation id="{op_id}">\n    <{group}><function name="{function}"><params>{inner}</params></function></{group}>\n  </operation>\n'


def loop(head: str, body: str) -> str:
    """``body`` inside the loop element ``head`` (for_each or repeat)."""
    return f"  {head}\n{body}  </{head[1:].split()[0]}>\n"


def nested(depth: int, body: str) -> str:
    """``body`` inside ``depth`` repeats, each with its own variable."""
    for level in range(depth):
        body = loop(f'<repeat count="1" var="v{level}">', body)
    return body


def mcap_chunks(inner: bytes, count: int) -> bytes:
    """An MCAP file of a header and ``count`` zstd chunks each holding ``inner`` (a few KB for megabytes of zeros)."""
    def record(opcode: int, body: bytes) -> bytes:
        return struct.pack("<BQ", opcode, len(body)) + body

    def text(value: str) -> bytes:
        return struct.pack("<I", len(value)) + value.encode()

    packed = zstandard.ZstdCompressor().compress(inner)
    chunk = record(0x06, struct.pack("<QQQI", 0, 0, len(inner), 0) + text("zstd") + struct.pack("<Q", len(packed)) + packed)
    return b"\x89MCAP0\r\n" + record(0x01, text("ros2") + text("crafted")) + chunk * count


def trace(*records: dict[str, object]) -> str:
    return "".join(json.dumps({"group": "left_arm", "operation": "1", "function": "wait", **r}) + "\n" for r in records)


#: The files rows name under {tmp}, as docs/faults.md describes them.
FILES: dict[str, str | bytes] = {
    "not_xml.xml": "this is not XML at all\n",
    "short_token": "secret\n",
    "shared_token": "C" * 43 + "\n",
    "collide.xml": (  # both hands to the middle of the table at once
        '<?xml version="1.0"?>\n<application name="colliding" robot="nextage">\n  <operation id="1">\n'
        '    <left_arm><function name="move_to"><params><param value="0.34,0.0,0.10,180deg,0,90deg"/></params></function></left_arm>\n'
        '    <right_arm><function name="move_to"><params><param value="0.34,0.0,0.10,180deg,0,90deg"/></params></function></right_arm>\n'
        '  </operation>\n</application>\n'
    ),
    "truncated.xml": RIVET[: len(RIVET) // 2],
    "entity.xml": '<?xml version="1.0"?>\n<!DOCTYPE a [<!ENTITY big "xxxxxxxx">]>\n<application name="t" robot="nextage">&big;</application>\n',
    "unknown_function.xml": app(op("left_arm", "fly_away")),
    "bad_param.xml": app(op("left_arm", "wait", "soon")),
    "missing_param.xml": app(op("right_arm", "pick_rivet")),
    "unknown_group.xml": app(op("left_leg", "gripper_open")),
    "missing_cell.xml": app(op("left_arm", "gripper_open"), cell="cells/nowhere.xml"),
    "unknown_robot.xml": app(op("arm", "gripper_open"), robot="r2d2"),
    "far_target.xml": app(op("left_arm", "move_to", "1e308,0,0.3,0,0,0")),
    "century_alarm.xml": app(op("left_arm", "gripper_open"), head='<error_policy action="alarm" alarm_timeout="3e9"/>\n'),
    "alarm.xml": RIVET.replace('cell="cells/rivet_cell.xml"', f'cell="{CELL}"').replace(
        '<error_policy retries="1" action="safe_pose" safe_pose="initial"/>', '<error_policy action="alarm"/>'
    ),
    "rivet.xml": RIVET.replace('cell="cells/rivet_cell.xml"', f'cell="{CELL}"'),
    "not_a_db.sqlite": "SQLite format? no: plain text\n",
    "rivet.trajectories.sqlite": "",
    "cp.sqlite": "",
    "run.jsonl": '{"event": "run_start", "t": 0}\n',
    "run.svg": '{"event": "run_start", "t": 0}\n',
    "rsi.xml": (ROOT / "config" / "kuka_rsi_ethernet.xml").read_text(),
    "rsi_no_aipos.xml": (ROOT / "config" / "kuka_rsi_ethernet.xml").read_text().replace('<ELEMENT TAG="DEF_AIPos" TYPE="DOUBLE" INDEX="INTERNAL"/>', ""),
    "rsi_onlysend.xml": (ROOT / "config" / "kuka_rsi_ethernet.xml").read_text().replace("<ONLYSEND>FALSE</ONLYSEND>", "<ONLYSEND>TRUE</ONLYSEND>"),
    "rsi_tech7.xml": (ROOT / "config" / "kuka_rsi_ethernet.xml").read_text().replace(
        '<ELEMENT TAG="DEF_Delay" TYPE="LONG" INDEX="INTERNAL"/>', '<ELEMENT TAG="DEF_Delay" TYPE="LONG" INDEX="INTERNAL"/><ELEMENT TAG="DEF_Tech.C7" TYPE="DOUBLE" INDEX="INTERNAL"/>'
    ),
    "zeros.mcap": mcap_chunks(bytes(64_000_000), 20),
    "unpacked.mcap": mcap_chunks(struct.pack("<BQ", 0x80, 64_000_000 - 9) + bytes(64_000_000 - 9), 20),
    "groups.jsonl": trace(*({"event": "function_start", "t": 0.01 * i, "group": f"g{i}"} for i in range(20_000))),
    "far_time.jsonl": trace({"event": "function_start", "t": 1.0}, {"event": "function_end", "t": 1e308, "outcome": "succeeded"}),
    "spoof.jsonl": trace({"event": "function_start", "t": 0.0}, {"event": "error", "t": 1.0, "error": "1\u202egnp.exe failed"}),
    "bidi_id.xml": app(op("left_arm", "gripper_open")).replace('<operation id="1">', '<operation id="1\u202egnp.exe">'),
    "huge.xml": b"<application>" + b" " * (33 * 1024 * 1024) + b"</application>",
    # loops and calls (issue 24)
    "loop_frame.xml": app(loop('<for_each var="hole" in="drill_1 drill_9">', op("left_arm", "debur_drilling", "{hole}", op_id="d_{hole}"))),
    "loop_param.xml": app(loop('<repeat count="2">', op("left_arm", "set_speed", "150%", op_id="s_{index}"))),
    "loop_variable.xml": app(loop('<for_each var="hole" in="drill_1">', op("left_arm", "debur_drilling", "{hol}", op_id="d_{hole}"))),
    "loop_id.xml": app(loop('<for_each var="hole" in="drill_1 drill_2">', op("left_arm", "debur_drilling", "{hole}", op_id="debur"))),
    "loop_kind.xml": app(loop('<for_each var="s" in="kind:screw">', op("right_arm", "gripper_open", op_id="o_{s}"))),
    "loop_grid.xml": app(loop('<for_each var="s" in="grid:rivet_1 2y2 0.03 0.03">', op("right_arm", "gripper_open", op_id="o_{s}"))),
    "loop_large.xml": app(loop('<repeat count="1000">', loop('<repeat count="1000" var="j">', op("right_arm", "gripper_open", op_id="o_{index}_{j}")))),
    "loop_deep.xml": app(nested(9, op("right_arm", "gripper_open", op_id="deep"))),
    "call_cycle.xml": app('  <call application="call_cycle.xml"/>\n'),
    "call_missing.xml": app('  <call application="blocks/nowhere.xml"><param name="hole" value="drill_1"/></call>\n'),
    "loop_collide.xml": app(loop('<for_each var="t" in="0.10 0.06 0.0">', (
        '  <operation id="reach_{index}">\n'
        '    <left_arm><function name="move_to"><params><param value="0.34,{t},0.10,180deg,0,90deg"/></params></function></left_arm>\n'
        '    <right_arm><function name="move_to"><params><param value="0.34,-{t},0.10,180deg,0,90deg"/></params></function></right_arm>\n'
        '  </operation>\n')), cell=""),
}
#: The mode each file is written with, whatever the umask the tests run under (a row about who may read
#: a file must not hold only under the usual 022); every other file: its owner's only.
FILES.update(MIXED_FILES)  # rows 250-259: mixed cells, each row naming the cell and the application
FILES.update(NAMED_FILES)  # rows 300-309: cells that name their robots' groups and joints
FILES.update(BRANCH_FILES)  # rows 240-249: outcome branches
FILES.update(BREAKPOINT_FILES)  # rows 260-269: breakpoints
FILES.update(PAUSED_EDIT_FILES)  # rows 280-289: a paused run's edit
FILES.update(ROLE_FILES)  # rows 320-329: the studio's users, tokens and audit log
MODES: dict[str, int] = {"shared_token": 0o644}
MODES.update(ROLE_MODES)


@dataclass(frozen=True)
class Row:
    number: int
    fault: str
    command: str
    message: str
    exit_code: int
    bound: float
    how: str

    @property
    def id(self) -> str:
        return f"{self.number:02d}-{re.sub(r'[^a-z0-9]+', '-', self.fault.lower()).strip('-')[:40]}"


def rows() -> list[Row]:
    """The table under '## The table' in docs/faults.md."""
    text = DOC.read_text()
    table = text[text.index("## The table"):]
    found = []
    for line in table.splitlines():
        if not re.match(r"^\| \d+ \|", line):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
        number, fault, command, message, code, bound, how = cells
        found.append(Row(int(number), fault, command.strip("`"), message.strip("`"), int(code), float(bound.rstrip(" s")), how))
    return found


def pattern(message: str, values: dict[str, str]) -> re.Pattern[str]:
    """The documented line as a regular expression: ``…`` stands for any text."""
    parts = [re.escape(fill(part, values)) for part in message.split("…")]
    return re.compile("^" + ".*".join(parts) + "$", re.MULTILINE)


def fill(text: str, values: dict[str, str]) -> str:
    for key, value in values.items():
        text = text.replace("{" + key + "}", value)
    return text


# ------------------------------------------------------------------------------ peers
def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.fixture
def peers() -> Iterator[dict[str, str]]:
    """Loopback peers: a silent TCP server, a full V+ simulator, a closed port, a quiet UDP port."""
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)  # the kernel completes the handshake; nobody ever reads or answers
    simulator = subprocess.Popen(
        [sys.executable, "-m", "robot_bridges.vplus.simulator", "--port", "0", "--max-clients", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT,
    )
    holder = socket.socket()
    try:
        assert simulator.stdout is not None
        banner = simulator.stdout.readline()  # "V+ simulator on 127.0.0.1:PORT (x1); Ctrl-C stops it"
        full_port = re.search(r":(\d+) ", banner)
        assert full_port, banner
        holder.connect(("127.0.0.1", int(full_port.group(1))))  # takes the only client slot
        yield {
            "silent_port": str(silent.getsockname()[1]),
            "full_port": full_port.group(1),
            "closed_port": str(free_port()),
            "udp_port": str(free_port(socket.SOCK_DGRAM)),
        }
    finally:
        holder.close()
        silent.close()
        simulator.terminate()
        simulator.wait(timeout=10)


def needs_peers(row: Row) -> bool:
    return any(f"{{{k}}}" in row.command for k in ("silent_port", "full_port", "closed_port", "udp_port"))


# ------------------------------------------------------------------------------ running
def run_in_process(argv: list[str], bound: float) -> tuple[int, str]:
    """``main(argv)`` on a worker thread, joined within ``bound`` s; everything it printed or logged."""
    out, err = io.StringIO(), io.StringIO()
    handler = logging.StreamHandler(err)  # a logged traceback would count as one
    logging.getLogger().addHandler(handler)
    result: list[int] = []
    worker = threading.Thread(target=lambda: result.append(main(argv, out, err)), name="cli row", daemon=True)
    try:
        worker.start()
        worker.join(bound)
    finally:
        logging.getLogger().removeHandler(handler)
    assert not worker.is_alive(), f"{argv} did not end within {bound:g} s"
    return result[0], out.getvalue() + err.getvalue()


def run_process(argv: list[str], bound: float, home: Path | None = None) -> tuple[int, str]:
    """``python -m execution_engine ARGV`` as a process of its own, ended within ``bound`` s.

    A ``launch`` row's cell talks DDS on loopback only, in a domain no other test uses meanwhile (in
    this session or another: dds_domain.py; two cells in one domain see each other's joints and
    machines), and every process it started is gone before that domain is given back; its machines'
    default trajectory database is in the row's folder, not the home directory."""
    with domain_env() as dds:
        env = {**os.environ, **dds}
        if home is not None:
            env["XDG_DATA_HOME"] = str(home)
        process = subprocess.Popen(  # stdin is no terminal: nobody at this run can answer an operator question
            [sys.executable, "-m", "execution_engine", *argv], cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, env=env, start_new_session=True,
        )
        try:
            out, err = process.communicate(timeout=bound)
        except subprocess.TimeoutExpired:
            stop_group(process)
            out, err = process.communicate()
            pytest.fail(f"{argv} did not end within {bound:g} s:\n{out}{err}")
        finally:
            stop_group(process)  # a node its launch left behind, too
    return process.returncode, out + err


ROWS = rows()


def test_the_table_has_at_least_40_kinds_of_fault_and_every_file_it_names_exists() -> None:
    assert len(ROWS) >= 40
    numbers = [r.number for r in ROWS]
    assert numbers == sorted(set(numbers)) and numbers[0] == 1  # in order, each once; blocks of numbers are handed out by area (140-159: ranges)
    assert len({r.fault for r in ROWS}) == len(ROWS)
    used = {name for r in ROWS for name in re.findall(r"\{tmp\}/([\w.]+)", r.command)}
    assert used - set(FILES) == {"nowhere.xml", "nowhere.users", "no"}  # paths that must not exist
    assert set(FILES) <= used
    assert all(r.how in ("in-process", "subprocess") for r in ROWS)


@pytest.mark.parametrize("row", ROWS, ids=[r.id for r in ROWS])
def test_row(row: Row, tmp_path: Path, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    write_files(row, tmp_path)
    values = {"tmp": str(tmp_path)}
    if needs_peers(row):
        values.update(request.getfixturevalue("peers"))
    argv = shlex.split(fill(row.command, values))
    assert argv[:3] == PREFIX, row.command
    if row.how == "in-process":
        code, output = run_in_process(argv[3:], row.bound)
    else:
        code, output = run_process(argv[3:], row.bound, tmp_path)
    assert "Traceback" not in output, output
    assert pattern(row.message, values).search(output), f"expected a line {row.message!r}, got:\n{output}"
    assert code == row.exit_code, output


def write_files(row: Row, folder: Path) -> None:
    """The files ``row`` names under {tmp}, each with its mode set (MODES), not left to the umask."""
    for name, content in FILES.items():
        if f"{{tmp}}/{name}" in row.command:
            path = folder / name
            path.write_bytes(content if isinstance(content, bytes) else content.encode())
            path.chmod(MODES.get(name, 0o600))


@pytest.mark.parametrize("umask", [0o077, 0o022, 0o000], ids=["077", "022", "000"])
def test_every_file_a_row_reads_has_its_mode_whatever_the_umask(umask: int, tmp_path: Path) -> None:
    previous = os.umask(umask)
    try:
        for row in ROWS:
            write_files(row, tmp_path)
    finally:
        os.umask(previous)
    written = {path.name: path.stat().st_mode & 0o777 for path in tmp_path.iterdir()}
    assert written == {name: MODES.get(name, 0o600) for name in written} and set(MODES) <= set(written)


@pytest.mark.parametrize("row", [r for r in ROWS if any(f"{{tmp}}/{name}" in r.command for name in MODES)], ids=lambda r: r.id)
def test_a_row_about_a_files_mode_holds_under_umask_077(row: Row, tmp_path: Path, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Under umask 077 a file the test had left to the umask would be its owner's only: row 92 held only under 022."""
    previous = os.umask(0o077)
    try:
        test_row(row, tmp_path, request, monkeypatch)
    finally:
        os.umask(previous)


def test_a_traceback_only_with_v(peers: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The same refused connection: one line for the operator; with -v, the traceback for a developer too."""
    monkeypatch.chdir(ROOT)
    argv = ["run", "apps_xml/vplus_pick_inspect.xml", "--no-check", "--host", "127.0.0.1", "--port", peers["closed_port"], "--backend-option", "retries=0"]
    code, quiet = run_in_process(argv, 60.0)
    verbose_code, verbose = run_in_process(["-v", *argv], 60.0)
    assert code == verbose_code == 5
    assert "Traceback" not in quiet and "Traceback (most recent call last)" in verbose
    line = next(line for line in quiet.splitlines() if line.startswith("error: cannot run"))
    assert line in verbose.splitlines()


def test_a_run_that_could_not_start_still_closes_its_trace_with_how_it_ended(peers: dict[str, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    trace = tmp_path / "run.jsonl"
    argv = ["run", "apps_xml/vplus_pick_inspect.xml", "--no-check", "--host", "127.0.0.1", "--port", peers["closed_port"],
            "--backend-option", "retries=0", "--trace", str(trace)]
    code, _ = run_in_process(argv, 60.0)
    summary = read_trace(trace)
    assert code == 5 and not summary.cut and summary.end is not None
    assert (summary.end["outcome"], summary.end["exit_code"], summary.end["operations_done"]) == ("error", 5, 0)
