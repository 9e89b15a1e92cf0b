"""The focus loop on V+ through the measurement port, measuring the sharpness of the inspection camera's images."""
from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
from test_vplus_app import APPS, Run, at_focus_distance, drive

from cell_runner.cli import main
from core_functions.primitives import Vision
from node_transport.clock import Clock
from robot_bridges.backend import BridgeError, FaultKind
from robot_bridges.vplus.camera_port import rendered_focus_camera


@pytest.mark.parametrize("start_mm", [-12.0, -5.0])
def test_the_focus_loop_ends_within_one_increment_of_the_sharpest_image(run_sim: Run, start_mm: float) -> None:
    async def main_(clock: Clock) -> tuple[float, list[float]]:
        camera = rendered_focus_camera(seed=4)
        sim, backend, library = await at_focus_distance(clock, start_mm / 1000, camera)  # type: ignore[arg-type]
        log: list[Any] = []
        await drive(library.focus_approach("focus_plane", step=0.002, speed=0.25), backend, log)
        tcp = backend.tcp_pose("arm")
        assert tcp is not None
        offset = library.cell.pose("focus_plane").inverse().compose(tcp).z
        values = [library.ctx.measurements[f"focus_plane.sharpness.{i}"] for i in range(len([p for p in log if isinstance(p, Vision)]))]
        await backend.close()
        await sim.close()
        return offset, values

    offset, values = run_sim(main_)
    assert abs(offset) <= 0.002 + 1e-6  # within one increment of the focus plane, where the image is sharpest
    assert values[-1] < values[-2] and all(a < b for a, b in zip(values[:-2], values[1:-1]))


def test_the_inspection_camera_does_not_locate(run_sim: Run) -> None:
    async def main_(clock: Clock) -> BridgeError:
        sim, backend, library = await at_focus_distance(clock, 0.0, rendered_focus_camera())  # type: ignore[arg-type]
        with pytest.raises(BridgeError) as error:
            await backend.execute("arm", Vision("locate", "focus_plane", nominal=library.cell.pose("focus_plane")))
        await backend.close()
        await sim.close()
        return error.value

    error = run_sim(main_)
    assert error.kind is FaultKind.VISION and "does not locate" in str(error)


def test_the_pick_and_inspect_application_runs_on_rendered_images(tmp_path: Path) -> None:
    trace = tmp_path / "trace.jsonl"
    out = io.StringIO()
    code = main(["run", str(APPS / "vplus_pick_inspect.xml"), "--speed", "max", "--trace", str(trace), "--backend-option", "camera=rendered"], out, out)
    assert code == 0, out.getvalue()
    events = [json.loads(line) for line in trace.read_text().splitlines()]
    reports = [e["result"]["report"] for e in events if e["event"] == "primitive_end" and (e.get("result") or {}).get("kind") == "vision"]
    assert reports and all(r["method"] == "sharpness" and r["camera"] == "inspection_camera" and r["image_size"] == [640, 480] for r in reports)
