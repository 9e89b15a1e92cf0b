"""The operator station's web server logs through the command's console: a warning uvicorn repeats is aggregated too.

uvicorn configured loggers of its own (handlers on ``uvicorn``, not propagating), so its warnings -- one per
invalid request a scanner sends -- went to stderr line by line past the console's aggregation.
"""
from __future__ import annotations

import io
import logging
import re

import pytest

pytest.importorskip("uvicorn", reason="the studio extra (starlette, uvicorn) is not installed")
from node_transport.console_log import ConsoleLog  # noqa: E402
from operator_station.serving import server_config  # noqa: E402


def test_uvicorn_warnings_reach_the_console_aggregated(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):  # as a fresh process has them (another test's server may have run)
        logger = logging.getLogger(name)
        monkeypatch.setattr(logger, "handlers", [])
        monkeypatch.setattr(logger, "propagate", True)
    server_config(lambda scope, receive, send: None, "127.0.0.1", 0)  # uvicorn configures its logging here
    assert logging.getLogger("uvicorn").handlers == [] and logging.getLogger("uvicorn").propagate
    stream = io.StringIO()
    with ConsoleLog(stream):
        for _ in range(500):
            logging.getLogger("uvicorn.error").warning("Invalid HTTP request received.")
    first, counted = stream.getvalue().splitlines()  # 500 warnings: two lines
    assert first == "WARNING uvicorn.error: Invalid HTTP request received."
    assert re.fullmatch(r"WARNING uvicorn\.error: Invalid HTTP request received\. \(x499 in the last [\d.e-]+ s\)", counted), counted
