"""Every third-party module a node can import under ``ros2 run``/``ros2 launch`` is declared in package.xml.

``rosdep install --from-paths`` installs what package.xml names and nothing else, so a module the
nodes import but package.xml does not declare makes a node die at start on a freshly set-up ROS
machine (``cv2`` did: every bridge imports the vision code).  The walk starts where ROS starts
code: each ``console_scripts`` entry point of setup.py and each file under ``launch/``.  It follows
every import of the project's own modules, module-level or inside a function, absolute or
relative, and every string that names a module of the project (``importlib.import_module`` of
``robot_bridges.registry``'s table, ``python -m execution_engine.recorder.encoder``).  An import
inside ``try: ... except ImportError`` is optional by design (the code runs on without it) and an
import under ``if TYPE_CHECKING:`` never runs; neither is required.
"""
from __future__ import annotations

import ast
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from lxml import etree

ROOT = Path(__file__).resolve().parents[1]

#: Python import name -> rosdep key (ros/rosdistro rosdep/*.yaml, or the ROS package of that name).
ROSDEP_KEYS = {
    "ament_index_python": "ament_index_python",
    "coal": "coal",  # pinocchio 3's collision library (Jazzy: pinocchio 4.1 on coal 3.0)
    "cv2": "python3-opencv",
    "hppfcl": "hpp-fcl",  # coal's former name, what pinocchio 2.7 ships
    "launch": "launch",
    "launch_ros": "launch_ros",
    "lxml": "python3-lxml",
    "matplotlib": "python3-matplotlib",
    "mcap": "mcap-ros2-support",  # no key of its own: mcap-ros2-support (pip) brings it
    "mcap_ros2": "mcap-ros2-support",
    "numpy": "python3-numpy",
    "orjson": "python3-orjson",
    "pinocchio": "pinocchio",
    "rcl_interfaces": "rcl_interfaces",
    "rclpy": "rclpy",
    "yaml": "python3-yaml",
}


#: Imported by the project only inside functions of another deployment: no ROS node runs them.
NOT_ON_ROS = {"cyclonedds": "the DDS transport (--transport dds, pip extra 'dds'); ROS nodes talk through rclpy"}


@dataclass
class Walk:
    """What the code reachable from some entry modules imports (third-party top-level names)."""

    modules: dict[str, Path] = field(default_factory=dict)  # own module name -> file
    required: dict[str, str] = field(default_factory=dict)  # name -> first file importing it unguarded
    at_load: set[str] = field(default_factory=set)  # the required names imported when a module loads (not in a function)
    alternatives: dict[frozenset[str], str] = field(default_factory=dict)  # try: import a / except ImportError: import b
    optional: dict[str, str] = field(default_factory=dict)  # only inside try/except ImportError with no fallback import


def _catches_import_error(handler: ast.ExceptHandler) -> bool:
    if handler.type is None:
        return True
    kinds = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return any(isinstance(k, ast.Name) and k.id in ("ImportError", "ModuleNotFoundError") for k in kinds)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


@dataclass
class _Found:
    name: str  # dotted, absolute
    lazy: bool  # inside a function: runs when called, not when the module loads


class _Imports(ast.NodeVisitor):
    """The imports of one file: unguarded, alternatives, optional; and its string constants."""

    def __init__(self, package: str) -> None:
        self.package = package
        self.found: list[_Found] = []
        self.alternatives: list[list[_Found]] = []
        self.optional: list[_Found] = []
        self.strings: list[str] = []
        self._depth = 0

    def _collect(self, statements: list[ast.stmt]) -> list[_Found]:
        outer, self.found = self.found, []
        for statement in statements:
            self.visit(statement)
        inner, self.found = self.found, outer
        return inner

    def visit_Try(self, node: ast.Try) -> None:
        if not any(_catches_import_error(h) for h in node.handlers):
            self.generic_visit(node)
            return
        tried = self._collect(node.body)
        fallback = self._collect([s for h in node.handlers for s in h.body])
        if fallback:
            self.alternatives.append(tried + fallback)
        else:
            self.optional += tried
        for statement in (*node.orelse, *node.finalbody):
            self.visit(statement)

    def visit_If(self, node: ast.If) -> None:
        if _is_type_checking(node.test):
            for statement in node.orelse:
                self.visit(statement)
            return
        self.generic_visit(node)

    def _function(self, node: ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) -> None:
        self._depth += 1
        self.generic_visit(node)
        self._depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = visit_Lambda = _function

    def visit_Import(self, node: ast.Import) -> None:
        self.found += [_Found(alias.name, self._depth > 0) for alias in node.names]

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level:
            parts = self.package.split(".") if self.package else []
            base = ".".join(parts[: len(parts) - node.level + 1])
            module = f"{base}.{node.module}" if node.module else base
        else:
            module = node.module or ""
        lazy = self._depth > 0
        self.found.append(_Found(module, lazy))
        self.found += [_Found(f"{module}.{alias.name}", lazy) for alias in node.names]

    def visit_Constant(self, node: ast.Constant) -> None:
        if isinstance(node.value, str):
            self.strings.append(node.value)


def own_packages(root: Path) -> set[str]:
    return {p.parent.name for p in root.glob("*/__init__.py")}


def module_file(root: Path, name: str) -> Path | None:
    base = root.joinpath(*name.split("."))
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    return None


def _third_party(found: Iterable[_Found], own: set[str]) -> list[_Found]:
    return [f for f in found if f.name and f.name.split(".")[0] not in own | set(sys.stdlib_module_names)]


def walk(root: Path, entry_modules: Iterable[str], entry_files: Iterable[Path] = ()) -> Walk:
    """Follow the project's own imports from ``entry_modules`` (dotted) and ``entry_files`` (scripts)."""
    own = own_packages(root)
    result = Walk()
    todo: list[tuple[str, Path | None]] = [(m, None) for m in entry_modules] + [("", f) for f in entry_files]
    while todo:
        name, path = todo.pop()
        if path is None:
            if name in result.modules:
                continue
            path = module_file(root, name)
            if path is None:
                continue
            result.modules[name] = path
            parts = name.split(".")
            todo += [(".".join(parts[:i]), None) for i in range(1, len(parts))]  # importing a.b.c runs a and a.b
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        visitor = _Imports(package)
        visitor.visit(ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
        where = path.relative_to(root).as_posix()
        everything = [*visitor.found, *visitor.optional, *(f for group in visitor.alternatives for f in group)]
        todo += [(f.name, None) for f in everything if f.name.split(".")[0] in own]
        for text in visitor.strings:  # "pkg.module" or "pkg.module:function" naming our own code
            dotted = text.partition(":")[0]
            if dotted.split(".")[0] in own and dotted.replace(".", "").replace("_", "").isalnum():
                todo.append((dotted, None))

        for f in _third_party(visitor.found, own):
            top = f.name.split(".")[0]
            result.required.setdefault(top, where)
            if not f.lazy:
                result.at_load.add(top)
        for group in visitor.alternatives:
            names = frozenset(f.name.split(".")[0] for f in _third_party(group, own))
            if names:
                result.alternatives.setdefault(names, where)
        for f in _third_party(visitor.optional, own):
            result.optional.setdefault(f.name.split(".")[0], where)
    for top in result.required:
        result.optional.pop(top, None)
    return result


def console_scripts(setup_py: Path) -> dict[str, str]:
    """``name -> module:function`` of setup.py's console_scripts, read from its source."""
    for node in ast.walk(ast.parse(setup_py.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == "console_scripts" and isinstance(value, ast.List):
                    entries = [str(ast.literal_eval(e)) for e in value.elts]
                    return {n.strip(): t.strip() for n, _, t in (e.partition("=") for e in entries)}
    raise AssertionError(f"{setup_py}: no console_scripts")


def declared(package_xml: Path) -> set[str]:
    """The keys package.xml declares for run time (exec_depend and depend)."""
    tree = etree.parse(str(package_xml))
    return {str(e.text).strip() for e in tree.iter("exec_depend", "depend")}


def entry_points() -> tuple[list[str], list[Path]]:
    scripts = console_scripts(ROOT / "setup.py")
    return sorted({target.partition(":")[0] for target in scripts.values()}), sorted((ROOT / "launch").glob("*.py"))


@pytest.fixture(scope="module")
def nodes_walk() -> Walk:
    """The walk from every node's entry (seconds of parsing): made once when this file's tests run (conftest keeps
    them on one worker), not when the file is imported, which every pytest-xdist worker does."""
    return walk(ROOT, *entry_points())


def test_every_third_party_import_of_a_node_is_declared_in_package_xml(nodes_walk: Walk) -> None:
    keys = declared(ROOT / "package.xml")
    needed = {name: where for name, where in nodes_walk.required.items() if name not in NOT_ON_ROS}
    named = set(needed) | {name for group in nodes_walk.alternatives for name in group}
    unmapped = sorted(named - set(ROSDEP_KEYS))
    assert not unmapped, f"imports with no rosdep key in ROSDEP_KEYS (add the key from ros/rosdistro rosdep/*.yaml): {unmapped}"
    missing = [f"{ROSDEP_KEYS[name]} (for import {name} in {where})" for name, where in sorted(needed.items()) if ROSDEP_KEYS[name] not in keys]
    missing += [
        f"one of {sorted(ROSDEP_KEYS[n] for n in group)} (for import {' or '.join(sorted(group))} in {where})"
        for group, where in nodes_walk.alternatives.items()
        if not any(ROSDEP_KEYS[n] in keys for n in group)
    ]
    assert not missing, "package.xml lacks <exec_depend> for: " + "; ".join(missing)


def test_what_ros_nodes_never_import_is_only_imported_inside_functions(nodes_walk: Walk) -> None:
    """NOT_ON_ROS may not hide a module a node imports when it starts."""
    assert set(NOT_ON_ROS) <= set(nodes_walk.required) | set(nodes_walk.optional)  # else the exemption is stale
    assert not (set(NOT_ON_ROS) & nodes_walk.at_load), {n: nodes_walk.required[n] for n in set(NOT_ON_ROS) & nodes_walk.at_load}


def test_the_walk_reaches_every_node_and_what_they_load_by_name(nodes_walk: Walk) -> None:
    """The check above is only as good as the walk: every executable's module, the back ends that
    robot_bridges.registry imports by name and the recorder's encoder process are reached, and the
    bridges' vision code with them."""
    scripts = console_scripts(ROOT / "setup.py")
    assert {"execution_engine", "group_machine", "nextage_sim_bridge", "vplus_bridge", "kuka_rsi_bridge"} <= set(scripts)
    expected = {target.partition(":")[0] for target in scripts.values()} | {
        "execution_engine.recorder.encoder",  # python -m, a string
        "robot_bridges.nextage_sim.backend",  # importlib.import_module from the registry's table
        "core_functions.vision.camera",
    }
    assert expected <= set(nodes_walk.modules), expected - set(nodes_walk.modules)
    assert {"launch", "launch_ros", "cv2", "numpy", "lxml", "mcap"} <= nodes_walk.at_load
    assert "rclpy" in nodes_walk.optional  # imported in a try that explains a missing ROS environment
    assert frozenset({"coal", "hppfcl"}) in nodes_walk.alternatives


def test_launch_files_start_only_installed_executables() -> None:
    """A launch file naming an executable setup.py does not install fails under ros2 launch only."""
    scripts = set(console_scripts(ROOT / "setup.py"))
    named: set[str] = set()
    for path in (ROOT / "launch").glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.keyword) and node.arg in ("executable", "bridge") and isinstance(node.value, ast.Constant):
                named.add(str(node.value.value))
    assert named and named <= scripts, named - scripts


def test_the_ros_setup_in_docs_installs_what_package_xml_declares_from_debian() -> None:
    """docs/ros2.md's set-up installs by hand what rosdep would: each python3-* key of package.xml."""
    text = (ROOT / "docs" / "ros2.md").read_text(encoding="utf-8")
    debian = sorted(k for k in declared(ROOT / "package.xml") if k.startswith("python3-"))
    assert debian and [k for k in debian if k not in text] == []


# ------------------------------------------------------------------ the walker on a tree of its own
def _tree(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text, encoding="utf-8")


def test_the_walker_follows_relative_nested_and_named_imports(tmp_path: Path) -> None:
    _tree(tmp_path, {
        "app/__init__.py": "import toplevel_of_init\n",
        "app/main.py": "from . import helper\nfrom .sub.deep import thing\n",
        "app/helper.py": "def f():\n    import numpy\n    return 'app.plugins.late:make'\n",
        "app/sub/__init__.py": "",
        "app/sub/deep.py": "from ..helper import f\nimport cv2\nthing = 1\n",
        "app/plugins/__init__.py": "",
        "app/plugins/late.py": "import lxml.etree\n",
        "app/unused.py": "import never_reached\n",
    })
    found = walk(tmp_path, ["app.main"])
    assert set(found.modules) == {"app", "app.main", "app.helper", "app.sub", "app.sub.deep", "app.plugins", "app.plugins.late"}
    assert set(found.required) == {"toplevel_of_init", "numpy", "cv2", "lxml"}
    assert found.required["cv2"] == "app/sub/deep.py"


def test_the_walker_leaves_out_optional_and_type_checking_imports(tmp_path: Path) -> None:
    _tree(tmp_path, {
        "app/__init__.py": "",
        "app/main.py": (
            "from typing import TYPE_CHECKING\n"
            "try:\n    import orjson\nexcept ImportError:\n    orjson = None\n"
            "try:\n    import yaml\nexcept ValueError:\n    pass\n"
            "try:\n    import coal\nexcept ImportError:\n    import hppfcl as coal\n"
            "def later():\n    import cyclonedds\n"
            "if TYPE_CHECKING:\n    import numpy\nelse:\n    import lxml\n"
        ),
    })
    found = walk(tmp_path, ["app.main"])
    assert set(found.required) == {"yaml", "lxml", "cyclonedds"}  # a try that does not catch ImportError guards nothing
    assert found.at_load == {"yaml", "lxml"}
    assert set(found.optional) == {"orjson"}
    assert set(found.alternatives) == {frozenset({"coal", "hppfcl"})}


@pytest.mark.parametrize("text", [
    '<package><exec_depend>python3-opencv</exec_depend><depend>rclpy</depend><test_depend>x</test_depend></package>',
])
def test_declared_reads_run_time_keys_only(tmp_path: Path, text: str) -> None:
    (tmp_path / "package.xml").write_text(text, encoding="utf-8")
    assert declared(tmp_path / "package.xml") == {"python3-opencv", "rclpy"}
