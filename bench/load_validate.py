"""Load + validate generated 10,000- and 50,000-operation applications, against a bare lxml parse of each file.

Usage: python bench/load_validate.py [--operations 10000 50000] [--repeat 5] [--hostile]

For each size the two are timed side by side in one process, interleaved (the order alternating
from round to round), ``--repeat`` rounds; each round gives a ratio load+validate / parse (CPU
time: steady on a shared machine; wall time printed too), and the median and the range of those
ratios are the figures.  Each side's time includes tidying the C heap after it (glibc's
``malloc_trim``): freeing a large tree otherwise leaves its cost to whichever side runs next.  Peak memory: each side once more in a fresh process of its own
(``VmHWM``: the resident peak, which counts libxml2's tree as well as Python's objects), the bare
parse with nothing but ``lxml.etree`` imported, the load with what it needs (the catalog); the
children alternate too.  Aims (issue 22): ratio <= 3x and peak <= 1.5x at both sizes.

With ``--hostile`` it then times the files that used to hang the validator, side by side with the
first size's load + validate, each with the peak memory of a fresh process validating it alone: a
5,000-frame parent chain; 100,000 unknown frames against a 200,000-frame cell; 31 MB of comments;
200,000 unknown elements; 100,000 frames with a bad name each; and a file of more elements than
the limit (refused before parsing).

The application is generated from the function catalog (the real one when app_functions is
importable, else a small stand-in) in the paper's Figure 6 layout, one function per group in
every operation, with a matching cell model; it must validate with zero diagnostics.  The ratio
says what the model, the schema, the positions and the semantic checks cost on top of parsing.
Last line: JSON.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import resource
import statistics
import subprocess
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
from execution_engine.app_model import MAX_ELEMENTS, count_problems, load_application, validate_application, validate_cell  # noqa: E402

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


COORDINATION = frozenset({"set_flag", "wait_flag"})  # a wait needs its partner's set: left out of a generated cycle


def plain(function: FunctionSpec, kind: str) -> bool:
    return (
        kind in function.group_kinds and function.sync is None and function.requires is None and function.leaves is None
        and function.name not in COORDINATION
    )


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


# ------------------------------------------------------------------------------ hostile files
def _chain(folder: Path) -> Path:
    frames = "".join(f'<frame name="f{i}" parent="{f"f{i - 1}" if i else "world"}"/>\n' for i in range(4999, -1, -1))
    return _write(folder / "chain.xml", f'<cell name="chain">\n{frames}</cell>\n')


def _unknown_frames(folder: Path) -> Path:
    (folder / "cells").mkdir(exist_ok=True)
    _write(folder / "cells" / "wide.xml", '<cell name="wide">\n' + "".join(
        f'<frame name="frame_{i}" xyz="0 0 0" kind="hole"/>\n' for i in range(200_000)) + "</cell>\n")
    ops = "".join(
        f'<operation id="{i}"><left_arm><function name="debur_drilling"><params><param value="nope_{i}"/></params></function></left_arm></operation>\n'
        for i in range(100_000)
    )
    return _write(folder / "unknown_frames.xml", f'<application name="a" robot="nextage" cell="cells/wide.xml">\n{ops}</application>\n')


def _comments(folder: Path) -> Path:
    return _write(folder / "comments.xml", '<cell name="c">' + "<!-- c -->" * 3_100_000 + "</cell>")


def _unknown_elements(folder: Path) -> Path:
    return _write(folder / "unknown_elements.xml", '<cell name="c">' + "<x/>" * 200_000 + "</cell>")


def _bad_names(folder: Path) -> Path:
    return _write(folder / "bad_names.xml", '<cell name="c">' + '<frame name="1"/>' * 100_000 + "</cell>")


def _too_many(folder: Path) -> Path:
    return _write(folder / "too_many.xml", '<cell name="c">' + "<x/>" * (7_000_000) + "</cell>")  # 28 MB


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


HOSTILE: dict[str, tuple[str, Callable[[Path], Path]]] = {  # each: what it is, how to write it into a folder
    "chain_5000": ("cell: a parent chain of 5,000 frames, children first", _chain),
    "unknown_frames": ("application: 100,000 unknown frames, cell of 200,000 frames", _unknown_frames),
    "comments": ("cell: 31 MB of comments", _comments),
    "unknown_elements": ("cell: 200,000 unknown elements", _unknown_elements),
    "bad_names": ("cell: 100,000 frames with a bad name", _bad_names),
    "too_many_elements": ("cell: 7,000,000 elements (28 MB), refused before parsing", _too_many),
}


def _validate(path: Path, functions: Catalog) -> list[object]:
    with open(path, "rb") as stream:
        head = stream.read(200)
    return list(validate_application(path, functions) if b"<application" in head else validate_cell(path))


def _one(case: str, folder: Path) -> int:
    """Child process: validate one hostile file once; print its problems and peak RSS."""
    functions, _ = catalog()
    path = folder / case
    found = _validate(path, functions)
    errors, warnings = count_problems(found)  # type: ignore[arg-type]
    print(json.dumps({"errors": errors, "shown": len(found), "max_rss_mb": _peak_rss_mb()}))
    return 0


def _peak_rss_mb() -> float:
    """This process's peak resident memory since it started (VmHWM: getrusage would count the
    parent's peak too, kept across exec)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def hostile(functions: Catalog, operations: int, baseline_ms: float, repeat: int) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    cases = {"baseline": (f"application: the {operations:,}-operation baseline", lambda folder: generate(functions, operations, folder)), **HOSTILE}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for case, (what, make) in cases.items():
            path = make(folder)
            child = subprocess.run(
                [sys.executable, __file__, "--one", str(path.relative_to(folder)), "--folder", str(folder)],
                capture_output=True, text=True, check=True,
            )
            alone = json.loads(child.stdout.strip().splitlines()[-1])
            wall, cpu = measure(lambda: _validate(path, functions), repeat)
            med = statistics.median
            rows.append({
                "case": case, "what": what, "file_mb": round(path.stat().st_size / 1e6, 2), "wall_ms": round(med(wall) * 1000, 1),
                "cpu_ms": round(med(cpu) * 1000, 1), "vs_baseline": round(med(wall) * 1000 / baseline_ms, 2),
                "errors": alone["errors"], "shown": alone["shown"], "max_rss_mb": round(alone["max_rss_mb"], 1),
            })
            row = rows[-1]
            print(f"{what:<62} {row['file_mb']:>6} MB  wall {row['wall_ms']:>8} ms  cpu {row['cpu_ms']:>8} ms  "
                  f"{row['vs_baseline']:>5}x baseline  peak {row['max_rss_mb']:>6} MB  {row['errors']:,} problems, {row['shown']} shown")
    return rows


#: The two sides' children, each importing only what its side needs: lxml.etree for the bare
#: parse; the catalog and the application model for the load (not this bench and its imports).
_MB = """
import json, sys

def mb(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) / 1024
"""
_BARE_PARSE = _MB + """
from lxml import etree
before = mb("VmRSS:")
etree.parse(sys.argv[1])
print(json.dumps({"before_mb": before, "peak_mb": mb("VmHWM:")}))
"""
_LOAD = _MB + """
sys.path.insert(0, sys.argv[2])
from app_functions.registry import full_catalog
from execution_engine.app_model import load_application
functions = full_catalog()
before = mb("VmRSS:")
load_application(sys.argv[1], functions)
print(json.dumps({"before_mb": before, "peak_mb": mb("VmHWM:")}))
"""


def _peak(kind: str, path: Path) -> dict[str, float]:
    root = str(Path(__file__).resolve().parent.parent)
    command = [sys.executable, "-c", _BARE_PARSE if kind == "parse" else _LOAD, str(path), root]
    child = subprocess.run(command, capture_output=True, text=True, check=False)
    if child.returncode != 0:  # its own words, not the command line of a CalledProcessError
        words = [line for line in child.stderr.splitlines() if line.strip()] or ["nothing on stderr"]
        raise SystemExit(f"the {kind} side's peak-memory process of {path.name} failed (exit {child.returncode}): {words[-1]}")
    return json.loads(child.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def _settled(action: Callable[[], object]) -> Callable[[], None]:
    """``action``, then glibc's heap tidied (``malloc_trim``) within the time taken.

    Freeing a tree of 10^5 libxml2 nodes leaves as many free chunks, which glibc sorts at the next
    large allocation: some 40 ms that would otherwise fall on whichever side runs next.  Each side
    pays for its own (nothing on a C library without ``malloc_trim``)."""
    trim = _malloc_trim()

    def run() -> None:
        action()
        if trim is not None:
            trim(0)
    return run


def _malloc_trim() -> Callable[[int], int] | None:
    try:
        return ctypes.CDLL(None).malloc_trim  # type: ignore[no-any-return]
    except (OSError, AttributeError):
        return None


def side_by_side(functions: Catalog, path: Path, repeat: int) -> dict[str, object]:
    """Parse and load + validate of one file, interleaved; then each side's peak in a fresh process."""
    parse_wall: list[float] = []
    parse_cpu: list[float] = []
    load_wall: list[float] = []
    load_cpu: list[float] = []
    for _ in range(2):  # warm-up: the schema, the catalog's caches, the file in the page cache
        etree.parse(str(path))
        load_application(path, functions)
    for round_ in range(repeat):
        sides = [("parse", _settled(lambda: etree.parse(str(path)))), ("load", _settled(lambda: load_application(path, functions)))]
        for name, action in sides if round_ % 2 == 0 else reversed(sides):
            (wall,), (cpu,) = measure(action, 1)
            (parse_wall if name == "parse" else load_wall).append(wall)
            (parse_cpu if name == "parse" else load_cpu).append(cpu)
    peaks: dict[str, list[dict[str, float]]] = {"parse": [], "load": []}
    for kind in ("parse", "load", "load", "parse"):
        peaks[kind].append(_peak(kind, path))
    ratios = [lc / pc for lc, pc in zip(load_cpu, parse_cpu)]
    wall_ratios = [lw / pw for lw, pw in zip(load_wall, parse_wall)]
    parse_peak = statistics.median(p["peak_mb"] for p in peaks["parse"])
    load_peak = statistics.median(p["peak_mb"] for p in peaks["load"])
    med = statistics.median
    return {
        "parse_cpu_ms": round(med(parse_cpu) * 1000, 1), "load_cpu_ms": round(med(load_cpu) * 1000, 1),
        "parse_wall_ms": round(med(parse_wall) * 1000, 1), "load_wall_ms": round(med(load_wall) * 1000, 1),
        "ratio_cpu_median": round(med(ratios), 2), "ratio_cpu_range": [round(min(ratios), 2), round(max(ratios), 2)],
        "ratio_wall_median": round(med(wall_ratios), 2), "ratio_wall_range": [round(min(wall_ratios), 2), round(max(wall_ratios), 2)],
        "parse_peak_mb": round(parse_peak, 1), "load_peak_mb": round(load_peak, 1), "peak_ratio": round(load_peak / parse_peak, 2),
        "parse_before_mb": round(med(p["before_mb"] for p in peaks["parse"]), 1),
        "load_before_mb": round(med(p["before_mb"] for p in peaks["load"]), 1),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operations", type=int, nargs="+", default=[10_000, 50_000])
    parser.add_argument("--repeat", type=int, default=5, help="interleaved rounds per size")
    parser.add_argument("--hostile", action="store_true", help="also time the files that used to hang the validator")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--folder", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        return _one(args.one, Path(args.folder))
    functions, source = catalog()
    print(f"catalog: {source} ({len(functions.functions)} functions); {args.repeat} interleaved rounds per size; aims: ratio <= 3x, peak <= 1.5x")
    rows: list[dict[str, object]] = []
    for operations in args.operations:
        with tempfile.TemporaryDirectory() as tmp:
            path = generate(functions, operations, Path(tmp))
            diagnostics = validate_application(path, functions)
            if diagnostics:
                for diagnostic in diagnostics[:20]:
                    print(diagnostic)
                print(f"the generated application has {len(diagnostics)} diagnostics; not benchmarking")
                return 1
            application = load_application(path, functions)
            calls = sum(len(op.calls) for op in application.operations)
            del application
            row: dict[str, object] = {"operations": operations, "calls": calls, "file_bytes": path.stat().st_size}
            row.update(side_by_side(functions, path, args.repeat))
        rows.append(row)
        low, high = row["ratio_cpu_range"]  # type: ignore[misc]
        print(
            f"{operations:>7,} operations ({calls:,} calls, {row['file_bytes'] / 1e6:.1f} MB): parse {row['parse_cpu_ms']} ms, "  # type: ignore[operator]
            f"load+validate {row['load_cpu_ms']} ms CPU (medians) -> ratio {row['ratio_cpu_median']}x [{low}-{high}] "
            f"(wall {row['ratio_wall_median']}x); peak {row['load_peak_mb']} vs {row['parse_peak_mb']} MB -> {row['peak_ratio']}x "
            f"(before the work: {row['load_before_mb']} vs {row['parse_before_mb']} MB)"
        )
    result: dict[str, object] = {"bench": "load_validate", "catalog": source, "repeat": args.repeat, "rows": rows}
    if args.hostile:
        first = rows[0]
        print(f"hostile files (each against the {first['operations']:,}-operation load + validate above; limit {MAX_ELEMENTS:,} elements):")
        result["hostile"] = hostile(functions, int(first["operations"]), float(first["load_wall_ms"]), max(1, min(args.repeat, 3)))  # type: ignore[arg-type]
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
