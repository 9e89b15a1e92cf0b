"""What loops cost at load time: an application written as loops against the same operations written out.

Usage: python bench/loop_expansion.py [--operations 1000 10000 40000] [--repeat 5]   (at most 40,000: one repeat of 10,000)

For each size two files that load to the same operations are timed side by side, interleaved (the
order alternating from round to round), ``--repeat`` rounds of ``load_application`` each (CPU time:
steady on a shared machine): the flat file, every operation written out (the rivet block of
apps_xml/rivet_installation.xml over the example cell's two holes, again and again), and the looped
one, a ``<repeat>`` around a ``<for_each var="hole" in="kind:hole">`` of the two operations (so the
expansion, the substitution in every id and param and the located offsets of every iteration are
what differs).  Figures: each side's median CPU per load and the median of the rounds' ratios
looped / flat; the two must load to equal operations (checked).  Last line: JSON.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app_functions.registry import full_catalog  # noqa: E402 -- after the repository is on the path
from execution_engine.app_model import load_application  # noqa: E402

CELL = ROOT / "apps_xml" / "cells" / "example_cell.xml"
HOLES = ("hole_a", "hole_b")
BLOCK = (
    '  <operation id="{prefix}debur_{hole}"><left_arm><function name="debur_drilling"><params><param value="{hole}"/></params></function></left_arm>'
    '<right_arm><function name="pick_rivet"><params><param value="slot_1"/><param value="ref_R10"/></params></function></right_arm></operation>\n'
    '  <operation id="{prefix}insert_{hole}"><right_arm><function name="insert_rivet"><params><param value="{hole}"/></params></function></right_arm></operation>\n'
)


def files(folder: Path, operations: int) -> tuple[Path, Path]:
    rounds = max(1, operations // (2 * len(HOLES)))
    head = f'<?xml version="1.0" encoding="UTF-8"?>\n<application name="bench" robot="nextage" cell="{CELL}">\n'
    flat = folder / f"flat_{operations}.xml"
    flat.write_text(head + "".join(
        BLOCK.replace("{prefix}", f"r{r}_").replace("{hole}", hole) for r in range(1, rounds + 1) for hole in HOLES
    ) + "</application>\n")
    looped = folder / f"looped_{operations}.xml"
    looped.write_text(head + f'  <repeat count="{rounds}" var="r">\n  <for_each var="hole" in="kind:hole">\n'
                      + BLOCK.replace("{prefix}", "r{r}_") + "  </for_each>\n  </repeat>\n</application>\n")
    return flat, looped


def timed(path: Path, catalog: object) -> tuple[float, object]:
    start = time.process_time()
    app = load_application(path, catalog)  # type: ignore[arg-type]
    return time.process_time() - start, app


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operations", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    catalog = full_catalog()
    results = []
    with tempfile.TemporaryDirectory() as folder:
        for operations in args.operations:
            flat, looped = files(Path(folder), operations)
            times: dict[str, list[float]] = {"flat": [], "looped": []}
            ratios = []
            for round_ in range(args.repeat):
                order = [("flat", flat), ("looped", looped)][:: 1 if round_ % 2 == 0 else -1]
                loaded = {}
                for name, path in order:
                    cpu, loaded[name] = timed(path, catalog)
                    times[name].append(cpu)
                same = [(o.id, {g: (c.function, c.params) for g, c in o.calls.items()}) for o in loaded["flat"].operations]  # type: ignore[attr-defined]
                assert same == [(o.id, {g: (c.function, c.params) for g, c in o.calls.items()}) for o in loaded["looped"].operations]  # type: ignore[attr-defined]
                ratios.append(times["looped"][-1] / times["flat"][-1])
            row = {
                "operations": len(same), "flat_cpu_s": statistics.median(times["flat"]), "looped_cpu_s": statistics.median(times["looped"]),
                "ratio_median": statistics.median(ratios), "ratio_min": min(ratios), "ratio_max": max(ratios),
            }
            results.append(row)
            print(f"{row['operations']:>7} operations: flat {row['flat_cpu_s'] * 1000:8.1f} ms CPU, looped {row['looped_cpu_s'] * 1000:8.1f} ms CPU, "
                  f"looped/flat {row['ratio_median']:.2f}x [{row['ratio_min']:.2f}-{row['ratio_max']:.2f}]")
    print(json.dumps({"bench": "loop_expansion", "results": results}))


if __name__ == "__main__":
    main()
