"""The static deadlock check's cost against the application's length, in a cell with interference zones.

Usage: python bench/zone_check.py TREE [TREE ...]   (each TREE a checkout, e.g. a ``git archive`` of another commit)

Loads the rivet demonstrator with its block repeated to 1,000, 4,000 and 10,000 operations (bench/studio_page.py's
``repeated_rivets``: every insert is in the rivet cell's zones) with each tree's code, one after the other, and prints
the CPU per load; linear growth means the check is no longer quadratic. Last line: one JSON object.
"""
import json
import subprocess
import sys

PROBE = """
import sys, tempfile, time
from pathlib import Path
ROOT = str(Path(sys.argv[1]).resolve()); sys.path.insert(0, ROOT); sys.path.insert(0, ROOT + "/bench")  # resolved: "." would link cells nowhere
from studio_page import repeated_rivets
from app_functions.registry import full_catalog
from execution_engine.app_model import load_application
catalog = full_catalog()
folder = Path(tempfile.mkdtemp())
(folder / "cells").symlink_to(Path(ROOT) / "apps_xml" / "cells")
for n in (1000, 4000, 10000):
    app = repeated_rivets(folder, n, f"r{n}")
    t = time.process_time(); load_application(str(app), catalog); print(n, time.process_time() - t)
"""


def main() -> int:
    trees = sys.argv[1:] or ["."]
    results = {}
    for tree in trees:
        lines = subprocess.run([sys.executable, "-c", PROBE, tree], check=True, capture_output=True, text=True, timeout=600).stdout.split()
        figures = {int(lines[i]): float(lines[i + 1]) for i in range(0, len(lines), 2)}
        results[tree] = figures
        print(tree, "  ".join(f"{n} ops: {s:.3f} s CPU" for n, s in figures.items()))
    print(json.dumps({"bench": "zone_check", "cpu_s": results}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
