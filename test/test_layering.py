"""The house rules of docs/architecture.md ("Packages and import rules"), held on the source by the import walk.

1. Packages in layers, imports pointing down only: ``core_functions`` -> ``node_transport`` ->
   ``app_functions`` | ``execution_engine`` | ``robot_bridges`` (which never import each other) ->
   ``cell_runner`` -> ``operator_station``.  Program entries (``__main__.py``) compose every layer and
   nothing imports them.
2. No import cycle between files; no underscore name of another module; an import inside a function only
   for a library that is optional or slow to load, with a comment saying which.
3. No Python file past 600 lines, tests, fakes, benches and launch files included.
And, so ROS 2 stays behind the transport port and settings stay typed below the command line: only the
rclpy transport imports rclpy; nothing below ``cell_runner`` takes an ``argparse.Namespace``.

The walk (``import_graph.py``) reads every import statement, type-only and function-level ones included.
"""
from __future__ import annotations

import ast
import subprocess
from pathlib import Path

import pytest

from import_graph import (
    HEAVY_MODULES,
    ROOT,
    Project,
    Walk,
    cycles,
    describe,
    function_level,
    graph,
    loads_at_import,
    private_imports,
    project_modules_in_functions,
    unexplained,
    walk,
)
from package_graph import arrows, block_in, is_entry, mermaid, package_of

MAX_LINES = 600


@pytest.fixture(scope="module")
def project() -> Walk:
    """The walk of every file of the project (seconds of parsing): made when this file's tests run, once -- the suite's
    conftest puts the tests sharing it on one worker -- rather than when it is imported, which every pytest-xdist
    worker and every ``--collect-only`` does."""
    return walk()


#: Each package and the packages it may import (its own always).
MAY_IMPORT: dict[str, set[str]] = {
    "core_functions": set(),
    "node_transport": {"core_functions"},
    "app_functions": {"core_functions", "node_transport"},
    "execution_engine": {"core_functions", "node_transport"},
    "robot_bridges": {"core_functions", "node_transport"},
    "cell_runner": {"core_functions", "node_transport", "app_functions", "execution_engine", "robot_bridges"},
    "operator_station": {"core_functions", "node_transport", "app_functions", "execution_engine", "robot_bridges", "cell_runner"},
}
BELOW_THE_COMMAND_LINE = ("core_functions", "node_transport", "app_functions", "execution_engine", "robot_bridges")
#: The rclpy transport: rclpy is imported there and nowhere else in the packages (launch files import ``launch``).
RCLPY_TRANSPORT = {"node_transport/ros.py"}


# ------------------------------------------------------------------------------------ 1. layers
def layer_violations(found: Walk) -> list[str]:
    """Every import of ``found`` from one package into another that it may not import."""
    wrong = []
    for i in found.imports:
        source, target = package_of(i.file), package_of(i.target) if i.target else None
        if source and target and source != target and not is_entry(i.file) and target not in MAY_IMPORT[source]:
            wrong.append(f"{describe(i)}  ({source} may import {', '.join(sorted(MAY_IMPORT[source])) or 'nothing of ours'})")
    return wrong


def test_every_package_imports_only_the_layers_below_it(project: Walk) -> None:
    wrong = layer_violations(project)
    assert wrong == [], "imports pointing up or across:\n" + "\n".join(wrong)


def test_an_import_up_or_across_is_found_type_only_and_in_functions_too(tmp_path: Path) -> None:
    files = {
        "core_functions/__init__.py": "", "node_transport/__init__.py": "import core_functions\n",
        "robot_bridges/__init__.py": "", "robot_bridges/sim.py": "from node_transport import port\n",
        "node_transport/port.py": "",
        "execution_engine/__init__.py": "",
        "execution_engine/engine.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from robot_bridges import sim\n",
        "execution_engine/__main__.py": "import cell_runner.cli\n",
        "cell_runner/__init__.py": "", "cell_runner/cli.py": "def main():\n    import operator_station  # optional\n",
        "operator_station/__init__.py": "",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text, encoding="utf-8")
    found = walk(Project(tmp_path, tuple(MAY_IMPORT), "test"))
    assert [line.split("  (")[0] for line in layer_violations(found)] == [
        "cell_runner/cli.py:2: operator_station [in function]  # optional",
        "execution_engine/engine.py:3: robot_bridges.sim [TYPE_CHECKING]",
    ]  # the entry's import of the command line is no violation


def test_the_rules_name_every_package_of_the_project() -> None:
    packages = {p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()}
    assert packages == set(MAY_IMPORT)


def test_nothing_imports_a_program_entry(project: Walk) -> None:
    wrong = [describe(i) for i in project.imports if i.target is not None and is_entry(i.target)]
    assert wrong == []


def test_the_program_entry_composes_the_command_line_with_the_station(project: Walk) -> None:
    """``python -m execution_engine`` is the whole program: every subcommand, the studio's too."""
    entry = {i.module for i in project.imports if i.file == "execution_engine/__main__.py" and i.target is not None}
    assert entry == {"operator_station.program"}
    assert {"cell_runner.cli", "operator_station.cli"} <= {i.module for i in project.imports if i.file == "operator_station/program.py"}


# -------------------------------------------------------------------------- 2. between files
def test_no_import_cycle_between_files(project: Walk) -> None:
    found = cycles(graph(project.imports))
    lines = []
    for component in found:
        members = set(component)
        lines.append(" <-> ".join(component))
        lines += [f"    {describe(i)}" for i in project.imports if i.file in members and i.target in members and i.target != i.file]
    assert found == [], "import cycles between files:\n" + "\n".join(lines)


def test_no_private_name_of_another_module_is_used(project: Walk) -> None:
    taken = [describe(i) for i in private_imports(project)]
    reached = [f"{u.file}:{u.line}: {u.module}.{u.name}" for u in project.private_uses]
    assert taken + reached == [], "underscore names of another module:\n" + "\n".join(taken + reached)


def test_every_function_level_import_says_why_it_is_not_at_the_top(project: Walk) -> None:
    lines = [describe(i) for i in unexplained(project.imports)]
    assert lines == [], "function-level imports without a comment saying the library is optional or slow:\n" + "\n".join(lines)


def test_no_function_level_import_of_the_projects_own_modules(project: Walk) -> None:
    lines = [describe(i) for i in project_modules_in_functions(project.imports)]
    assert lines == [], "the project's own modules imported inside functions (import them at the top):\n" + "\n".join(lines)


@pytest.mark.parametrize(("module", "library"), sorted(HEAVY_MODULES.items()))
def test_a_project_module_imported_in_a_function_really_loads_its_heavy_library(module: str, library: str, project: Walk) -> None:
    """The exemption is true (importing the module loads the library) and used (some function imports it)."""
    assert library in loads_at_import(project, module)
    assert any(i.module == module for i in function_level(project.imports))


# ------------------------------------------------------------------------------ 3. file length
def python_files() -> list[str]:
    """Every Python file of the repository as committed or about to be (tests, benches, launch files too)."""
    listed = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard", "*.py"], cwd=ROOT, capture_output=True, text=True, check=False,
    )
    if listed.returncode == 0 and listed.stdout.strip():
        return [f for f in listed.stdout.split() if (ROOT / f).is_file()]
    skip = {".venv", "build", "install", "log"}  # no git (a source archive): walk the tree
    return [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.py") if not skip & set(p.relative_to(ROOT).parts)]


def test_no_python_file_is_past_600_lines() -> None:
    files = python_files()
    assert {"setup.py", "test/test_layering.py", "launch/nextage_sim.launch.py", "bench/dry_run.py"} <= set(files)
    long = sorted(
        (n, f) for f in files if (n := len((ROOT / f).read_text(encoding="utf-8").splitlines())) > MAX_LINES
    )
    assert long == [], "files past 600 lines: " + ", ".join(f"{f} ({n})" for n, f in long)


# --------------------------------------------------------------------- ROS 2 and typed settings
def test_only_the_rclpy_transport_imports_rclpy(project: Walk) -> None:
    wrong = [
        describe(i) for i in project.imports
        if package_of(i.file) and i.module.split(".")[0] in ("rclpy", "rosidl_runtime_py", "launch", "launch_ros") and i.file not in RCLPY_TRANSPORT
    ]
    assert wrong == []


def _namespace_uses(file: str) -> list[str]:
    """Where ``file`` names argparse's Namespace or ArgumentParser outside a program's own ``main``/``_parser``."""
    tree = ast.parse((ROOT / file).read_text(encoding="utf-8"))
    found = []

    def visit(node: ast.AST, inside: str | None) -> None:
        for child in ast.iter_child_nodes(node):
            name = child.name if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) else inside
            if isinstance(child, ast.Attribute) and child.attr in ("Namespace", "ArgumentParser") and name not in ("main", "_parser"):
                found.append(f"{file}:{child.lineno}: argparse.{child.attr} in {name or 'the module'}")
            visit(child, name)

    visit(tree, None)
    return found


def test_nothing_below_the_command_line_sees_argparse(project: Walk) -> None:
    """Below ``cell_runner`` settings travel as dataclasses.  argparse appears there only in a program of its own
    (the controller simulators, the interface schema writer: a ``main`` parsing its own command line, whose
    Namespace never leaves it) and in ``option_ranges.argument_type``, a ``type=`` converter that sees one string."""
    importers = sorted({i.file for i in project.imports if i.module == "argparse" and package_of(i.file) in BELOW_THE_COMMAND_LINE})
    programs = [f for f in importers if "__main__" in (ROOT / f).read_text(encoding="utf-8")]
    assert sorted(set(importers) - set(programs)) == ["core_functions/option_ranges.py"]
    uses = [use for f in importers for use in _namespace_uses(f)]
    assert uses == []
    signatures = [
        f"{file}:{node.lineno}: {node.name}({ast.unparse(arg)})"
        for file in project.files if package_of(file) in BELOW_THE_COMMAND_LINE
        for node in ast.walk(ast.parse((ROOT / file).read_text(encoding="utf-8")))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        for arg in (*node.args.args, *node.args.kwonlyargs) if arg.annotation is not None and "Namespace" in ast.unparse(arg.annotation)
    ]
    assert signatures == []


# --------------------------------------------------------------------------------- the picture
def test_the_architecture_opens_with_the_package_graph_drawn_from_the_imports_now(project: Walk) -> None:
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    drawn = block_in(text)
    assert drawn is not None, "docs/architecture.md has no package graph: .venv/bin/python test/package_graph.py --write docs/architecture.md"
    assert text.index(drawn) < text.index("\n## "), "the package graph comes before the first section"
    assert drawn == mermaid(project), "the package graph is stale: .venv/bin/python test/package_graph.py --write docs/architecture.md"


def test_the_picture_counts_each_file_to_module_import_once_and_leaves_entries_out(project: Walk) -> None:
    counted = arrows(project)
    assert set(counted) == {(a, b) for a, allowed in MAY_IMPORT.items() for b in allowed if counted.get((a, b))}
    assert ("execution_engine", "operator_station") not in counted  # only __main__.py names the station
    by_hand = {(i.file, i.target) for i in project.imports if i.target and package_of(i.file) == "app_functions" and package_of(i.target) == "core_functions"}
    assert counted[("app_functions", "core_functions")] == len(by_hand) > 0
