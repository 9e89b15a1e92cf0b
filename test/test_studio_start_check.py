"""The studio's Start is checked from where the robot is, as ``run`` is (issue 20, finding 4).

The station's dry run before connecting starts the simulator in its start pose; here the robot
the station connects to is somewhere else (the Nextage simulator in its ``off`` pose, the arms
folded back): the run is dry-run again from the joints the back end reports, starts with the way
back the dry run proved, and the page says so.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the studio extra (starlette, uvicorn) is not installed")

import robot_bridges.registry as registry  # noqa: E402
from test_studio_server import cell_dir, rivet, run_to_end  # noqa: E402, F401 - cell_dir is a fixture


def test_a_robot_away_from_the_start_is_brought_back_first_and_the_page_says_so(cell_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    connect = registry.create_backend

    async def folded(name: str, clock: Any, options: Any) -> Any:  # the robot the station connects to, not the dry run's
        return await connect(name, clock, replace(options, extra={**options.extra, "initial_pose": "off"}))

    monkeypatch.setattr(registry, "create_backend", folded)
    station, client, document = rivet(cell_dir)
    run_to_end(station, client, "rivet_installation.xml", document)
    said = [m["message"] for m in station.feed.snapshot.messages]
    assert any("the robot is not where rivet_installation starts" in m and "the run starts with the way back" in m for m in said), said
    assert any(m == "application rivet_installation (way back): FINISHED" for m in said), said
    assert station.session is not None and station.session.report is not None
    assert station.session.report.outcome == "finished" and station.session.report.operations_done == 10
