"""Load + validate a generated 10,000-operation application, against a bare lxml parse of the same file.

Usage: python bench/load_validate.py [--operations 10000] [--repeat 5]

The application is generated from the function catalog (the real one when app_functions is
importable, else a small stand-in) in the paper's Figure 6 layout, one function per group in
every operation, with a matching cell model; it must validate with zero diagnostics.  The same
run times ``lxml.etree.parse`` of the file as the baseline, so the ratio says what the model,
the schema, the positions and the semantic checks cost on top of parsing.  Last line: JSON.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from xml.sax.saxutils import quoteattr

from lxml import etree

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from core_functions.catalog import Catalog, FunctionSpec, Hold, ParamSpec, ParamType, skill  # noqa: E402
from core_functions.robots import NEXTAGE_OPEN, RobotModel  # noqa: E402
from execution_engine.app_model import load_application, validate_application  # noqa: E402

FRAMES_PER_KIND = 20


class _StandIn:
    """Used only when the real catalog is not importable."""

    @skill(groups=("arm", "torso_head"))
    def wait(self) -> None:
        """Sit out."""

    @skill(ParamSpec("hole", ParamType.FRAME, "hole", kinds=("hole",)))
    def debur_drilling(self, hole: str) -> None:
        """Debur."""

    @skill(ParamSpec("slot", ParamType.FRAME, "slot", kinds=("rivet_slot",)), ParamSpec("ref", ParamType.ELEMENT, "ref", kinds=("rivet",)),
           requires=Hold.NOTHING, leaves=Hold.PART)
    def pick_rivet(self, slot: str, ref: str) -> None:
        """Pick."""

    @skill(ParamSpec("hole", ParamType.FRAME, "hole", kinds=("hole",)), requires=Hold.PART, leaves=Hold.NOTHING)
    def insert_rivet(self, hole: str) -> None:
        """Insert."""


def catalog() -> tuple[Catalog, str]:
    try:
        from app_functions.registry import full_catalog
    except ImportError:
        return Catalog.from_classes({"stand_in": _StandIn}), "stand-in"
    return full_catalog(), "real"


# ------------------------------------------------------------------------------ generation
class Generator:
    """Fills every param of a function with a value its ParamSpec accepts, from a generated cell."""

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot
        self.frame_kinds: set[str] = set()
        self.element_kinds: set[str] = set()

    def frame(self, spec: ParamSpec, index: int) -> str:
        kind = spec.kinds[index % len(spec.kinds)] if spec.kinds else "fixture"
        self.frame_kinds.add(kind)
        return f"{kind}_{index % FRAMES_PER_KIND}"

    def value(self, spec: ParamSpec, group: str, index: int) -> str | None:
        if spec.default is not None:
            return spec.default
        if spec.type in (ParamType.FRAME, ParamType.TARGET):
            return self.frame(spec, index)
        if spec.type is ParamType.FRAMES:
            return f"{self.frame(spec, index)} {self.frame(spec, index + 1)}"
        if spec.type is ParamType.ELEMENT:
            kind = spec.kinds[0] if spec.kinds else "part"
            self.element_kinds.add(kind)
            return f"{kind}_ref"
        if spec.type is ParamType.NUMBER or spec.type is ParamType.INTEGER:
            low = spec.minimum if spec.minimum is not None else 0.0
            high = spec.maximum if spec.maximum is not None else low + 1.0
            middle = (low + high) / 2
            return str(int(middle)) if spec.type is ParamType.INTEGER else f"{middle:.4f}"
        if spec.type is ParamType.JOINTS:
            return " ".join(f"{v:.4f}" for v in self.robot.group_pose("initial", group))
        simple: dict[ParamType, Callable[[], str]] = {
            ParamType.BOOLEAN: lambda: "true",
            ParamType.TEXT: lambda: "bench",
            ParamType.CHOICE: lambda: spec.choices[0],
            ParamType.NAME: lambda: f"bench_{index % 7}",
            ParamType.JOINT_POSE: lambda: "initial",
        }
        make = simple.get(spec.type)
        return make() if make else None  # GROUP: only synchronised functions, which are left out

    def call(self, function: FunctionSpec, group: str, index: int) -> str | None:
        values = [self.value(p, group, index) for p in function.params]
        if any(v is None for v in values):
            return None
        params = "".join(f"\n          <param value={quoteattr(v or '')}></param>" for v in values)
        body = f"\n        <params>{params}\n        </params>\n      " if values else ""
        return f"      <function name={quoteattr(function.name)}>{body}</function>"

    def cell(self) -> str:
        frames = []
        for k, kind in enumerate(sorted(self.frame_kinds)):
            children = "\n".join(
                f'    <frame name="{kind}_{i}" xyz="{0.01 * i:.3f} 0 0" rpy="3.14159265 0 0" kind="{kind}" element="rivet_ref"/>'
                if kind == "rivet_slot" and "rivet" in self.element_kinds
                else f'    <frame name="{kind}_{i}" xyz="{0.01 * i:.3f} 0 0" rpy="3.14159265 0 0" kind="{kind}"/>'
                for i in range(FRAMES_PER_KIND)
            )
            frames.append(f'  <frame name="base_{kind}" xyz="0.4 {0.1 * k - 0.2:.2f} 0.05">\n{children}\n  </frame>')
        elements = [f'  <element name="{kind}_ref" kind="{kind}" diameter="0.0048" length="0.010"/>' for kind in sorted(self.element_kinds)]
        return '<?xml version="1.0" encoding="UTF-8"?>\n<cell name="bench_cell">\n' + "\n".join(frames + elements) + "\n</cell>\n"


def plain(function: FunctionSpec, kind: str) -> bool:
    return kind in function.group_kinds and function.sync is None and function.requires is None and function.leaves is None


def generate(catalog: Catalog, operations: int, folder: Path) -> Path:
    """An application cycling through the catalog's functions; the right arm picks and places."""
    robot = NEXTAGE_OPEN
    gen = Generator(robot)
    functions = [catalog.functions[n] for n in catalog.names()]
    pickers = [f for f in functions if f.requires is Hold.NOTHING and f.leaves is Hold.PART and not f.sync]
    placers = [f for f in functions if f.requires is Hold.PART and f.leaves is Hold.NOTHING and not f.sync]
    ops: list[str] = []
    for i in range(operations):
        groups: list[str] = []
        for g, group in enumerate(robot.group_names):
            kind = robot.group(group).kind
            chosen: str | None = None
            if group == "right_arm" and pickers and placers:
                chosen = gen.call((pickers if i % 2 == 0 else placers)[0], group, i)
            candidates = [f for f in functions if plain(f, kind)]
            offset = i + g
            while chosen is None and candidates:
                chosen = gen.call(candidates[offset % len(candidates)], group, i)
                offset += 1
            groups.append(f"    <{group}>\n{chosen}\n    </{group}>")
        ops.append(f'  <operation id="{i + 1}">\n' + "\n".join(groups) + "\n  </operation>")
    (folder / "cells").mkdir(exist_ok=True)
    (folder / "cells" / "bench_cell.xml").write_text(gen.cell())
    path = folder / "bench_application.xml"
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<application name="bench" robot="nextage" cell="cells/bench_cell.xml">\n' + "\n".join(ops) + "\n</application>\n"
    )
    return path


def measure(action: Callable[[], object], repeat: int) -> tuple[list[float], list[float]]:
    """Wall and CPU seconds of each run; CPU time stays meaningful when other jobs share the cores."""
    wall, cpu = [], []
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        action()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return wall, cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operations", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    functions, source = catalog()
    with tempfile.TemporaryDirectory() as tmp:
        path = generate(functions, args.operations, Path(tmp))
        diagnostics = validate_application(path, functions)
        if diagnostics:
            for diagnostic in diagnostics[:20]:
                print(diagnostic)
            print(f"the generated application has {len(diagnostics)} diagnostics; not benchmarking")
            return 1
        application = load_application(path, functions)
        calls = sum(len(op.calls) for op in application.operations)
        size = path.stat().st_size
        parse, parse_cpu = measure(lambda: etree.parse(str(path)), args.repeat)
        load, load_cpu = measure(lambda: load_application(path, functions), args.repeat)
    med = statistics.median
    print(f"catalog: {source} ({len(functions.functions)} functions); file: {args.operations} operations, {calls} calls, {size / 1e6:.2f} MB")
    print(f"baseline lxml.etree.parse: wall median {med(parse) * 1000:.1f} ms (min {min(parse) * 1000:.1f}), cpu median {med(parse_cpu) * 1000:.1f} ms")
    print(f"load + validate:           wall median {med(load) * 1000:.1f} ms (min {min(load) * 1000:.1f}), cpu median {med(load_cpu) * 1000:.1f} ms")
    print(f"ratio load+validate / parse: wall {med(load) / med(parse):.1f}x, cpu {med(load_cpu) / med(parse_cpu):.1f}x; "
          f"target <= 1000 ms: {'met' if med(load) <= 1.0 else 'missed'} (wall), {'met' if med(load_cpu) <= 1.0 else 'missed'} (cpu)")
    print(json.dumps({
        "bench": "load_validate",
        "catalog": source,
        "operations": args.operations,
        "calls": calls,
        "file_bytes": size,
        "repeat": args.repeat,
        "parse_ms_median": round(med(parse) * 1000, 2),
        "parse_cpu_ms_median": round(med(parse_cpu) * 1000, 2),
        "load_validate_ms_median": round(med(load) * 1000, 2),
        "load_validate_ms_min": round(min(load) * 1000, 2),
        "load_validate_cpu_ms_median": round(med(load_cpu) * 1000, 2),
        "ratio_median": round(med(load) / med(parse), 2),
        "ratio_cpu_median": round(med(load_cpu) / med(parse_cpu), 2),
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
