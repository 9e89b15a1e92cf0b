"""The studio's 3D view in headless Chromium: the frame time of the Nextage rivet cell, and a replay's slider.

Usage: python bench/studio_3d.py [--frames 240] [--positions 100] [--width 1280 --height 800]

A recording of the rivet demonstrator (``run --speed max --record``) is replayed in the station and its 3D tab
shown at ``--width`` x ``--height``: the robot from its URDF, the cell, the goals, the located holes.

1. ``--frames`` frames drawn back to back with the camera turning (``view3d.measure``: every frame redrawn), the
   mean and worst time the renderer takes for one (``render_ms``) and the frame interval the browser kept; the
   baseline is the same renderer drawing the floor alone (robots, cell and marks hidden), so the ratio says what the
   scene costs over an empty frame.  Draw calls, triangles, and the geometries and textures the renderer holds before
   and after (equal: nothing is made per frame).  Aim: <= 16.7 ms a frame (60 fps).  Headless Chromium draws with
   SwiftShader, WebGL on the CPU: a laptop's GPU draws the same scene in a fraction of that time.
2. ``--positions`` slider positions across the recording, each the time ``view3d.update`` takes to put the robot,
   goals, located frames and findings at that instant (the work the slider does before a frame is drawn).

Last line: JSON.  Needs Debian's chromium and chromium-driver, and the studio extra.
"""
from __future__ import annotations

import argparse
import io
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from app_functions.registry import full_catalog  # noqa: E402
from cell_runner.cli import main as run_main  # noqa: E402
from operator_station import browser  # noqa: E402
from operator_station.cli import build_station  # noqa: E402
from operator_station.testing import serve, station_args, until as wait  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=240)
    parser.add_argument("--positions", type=int, default=100)
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=800)
    args = parser.parse_args()
    if browser.missing():
        print(json.dumps({"error": browser.missing()}))
        return 2
    with tempfile.TemporaryDirectory(prefix="bench_3d_") as name:
        folder = Path(name)
        shutil.copytree(ROOT / "apps_xml" / "cells", folder / "cells")
        shutil.copy(ROOT / "apps_xml" / "rivet_installation.xml", folder / "rivet_installation.xml")
        recording = folder / "rivet.mcap"
        if run_main(["run", str(folder / "rivet_installation.xml"), "--speed", "max", "-q", "--record", str(recording)], io.StringIO(), io.StringIO()) != 0:
            raise RuntimeError("the recording could not be made")
        served = serve(build_station(station_args(replay=str(recording), no_check=True), full_catalog(), folder))
        driver = browser.chromium(args.width, args.height + 200)
        try:
            driver.get(served.url)
            wait(driver, "document.body.dataset.ready === 'true' && view3d.ready() && view3d.located().length > 0")
            driver.find_element("id", "tab-view3d").click()
            end = driver.execute_script("return Store.now()")
            driver.execute_script("Store.setCursor(arguments[0] / 2)", end)
            time.sleep(0.5)
            before = driver.execute_script("return view3d.frameStats()")
            scene = driver.execute_async_script("view3d.measure(arguments[0]).then(arguments[arguments.length - 1])", args.frames)
            bare = driver.execute_async_script("view3d.measure(arguments[0], true).then(arguments[arguments.length - 1])", args.frames)
            updates = driver.execute_script("""
                const n = arguments[0], end = arguments[1], ms = [];
                for (let k = 0; k < n; k++) { Store.cursor = end * k / (n - 1); const t0 = performance.now(); view3d.update(); ms.push(performance.now() - t0); }
                Store.setCursor(null);
                return ms;""", args.positions, end)
        finally:
            driver.quit()
            served.close()
    summary = {
        "width": args.width, "height": args.height, "frames": args.frames,
        "scene": {k: scene[k] for k in ("render_ms_mean", "render_ms_max", "interval_ms_mean", "fps", "calls", "triangles", "geometries", "textures")},
        "bare": {k: bare[k] for k in ("render_ms_mean", "render_ms_max", "interval_ms_mean", "fps", "calls", "triangles")},
        "held_before": {"geometries": before["geometries"], "textures": before["textures"]},
        "ratio": scene["render_ms_mean"] / bare["render_ms_mean"] if bare["render_ms_mean"] else None,
        "slider": {"positions": len(updates), "update_ms_median": statistics.median(updates), "update_ms_max": max(updates)},
        "recording_s": end,
    }
    print(f"3D view, the rivet cell at {args.width}x{args.height}: {scene['render_ms_mean']:.2f} ms a frame (worst {scene['render_ms_max']:.2f}), "
          f"{scene['calls']} draw calls, {scene['triangles']:,} triangles; the floor alone {bare['render_ms_mean']:.2f} ms; "
          f"geometries held {before['geometries']} -> {scene['geometries']}; slider update median {summary['slider']['update_ms_median']:.2f} ms")
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
