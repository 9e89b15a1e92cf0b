"""The simulator as a program: arguments, a real connection, and stopping on SIGTERM."""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys

import pytest

from robot_bridges.vplus import codec
from robot_bridges.vplus.simulator import main


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--port", "70000"], "error: --port must be a whole number in [0, 65535], got 70000"),
        (["--speed", "0"], "error: --speed must be a number in [0.01, 1000] x real time, got 0"),
        (["--speed", "1e308"], "error: --speed must be a number in [0.01, 1000] x real time, got 1e+308"),
        (["--max-clients", "0"], "error: --max-clients must be a whole number in [1, 1000], got 0"),
        (["--max-clients", "1000000"], "error: --max-clients must be a whole number in [1, 1000], got 1000000"),
        (["--idle-timeout", "0"], "error: --idle-timeout must be a number in [0.001, 86400] s, got 0"),
        (["--idle-timeout", "inf"], "error: --idle-timeout must be a number in [0.001, 86400] s, got inf"),
        (["--reclaim-after", "-1"], "error: --reclaim-after must be a number in [0.001, 86400] s, got -1"),
        (["--reclaim-after", "1e9"], "error: --reclaim-after must be a number in [0.001, 86400] s, got 1e+09"),
        (["--run-for", "inf"], "error: --run-for must be a number in [0.001, 604800] s, got inf"),
        (["--run-for", "-5"], "error: --run-for must be a number in [0.001, 604800] s, got -5"),
    ],
)
def test_bad_arguments_are_refused_with_a_clear_message(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_a_bounded_run_stops_by_itself(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--port", "0", "--speed", "100", "--run-for", "1"]) == 0  # 1 s of run time at 100x
    assert re.search(r"V\+ simulator on 127\.0\.0\.1:\d+", capsys.readouterr().out)


def test_the_module_serves_acks_and_stops_on_sigterm() -> None:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "robot_bridges.vplus.simulator", "--port", "0", "--speed", "50"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert proc.stdout is not None
        banner = proc.stdout.readline()
        port = int(re.search(r":(\d+) ", banner).group(1))  # type: ignore[union-attr]
        with socket.create_connection(("127.0.0.1", port), timeout=10) as conn:
            conn.settimeout(10)
            conn.sendall(codec.Message("a1b2c3d4", codec.ENABLE_AIR).encode())
            data = b""
            while not data.endswith(b"\r\n"):
                data += conn.recv(256)
        ack = codec.decode_ack(data[:-2])
        assert ack.id == "a1b2c3d4" and ack.pose[:3] == pytest.approx((480, 0, 710), abs=1e-3)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
