"""The project's imports between files, read from the source (an AST walk, nothing outside the project).

Issue 21 asks for no import cycle between files, no private (underscore) name taken from another module, and
imports inside functions only for a library that is optional or slow to load, each saying which in a comment.
This module finds what those rules are about, so a test holds them (``test_import_graph.py``, later the layering
test) and a person can look: ``python test/import_graph.py`` prints every file's project imports, the cycles,
the private names taken and the function-level imports.

What counts as an import: every ``import``/``from ... import`` statement, at module level or inside a function,
under ``if TYPE_CHECKING:`` too (a type-only import still ties one file's design to the other, and that is how
cycles get hidden).  ``from m import n`` is an import of the file ``m/n.py`` when that is a submodule, else of
``m``'s file taking the name ``n``; relative imports are resolved from the importing file's package.  Files
under ``test/`` are top-level modules (pytest puts ``test/`` on ``sys.path``: ``import ros_fakes``).  Importing
``a.b.c`` also runs the ``__init__`` of ``a`` and ``a.b``; those implicit edges are left out, else every package
whose ``__init__`` re-exports its submodules would be a cycle with each of them.
"""
from __future__ import annotations

import ast
import io
import re
import sys
import tokenize
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The packages of the project; ``test`` holds top-level modules (helpers and tests).
PACKAGES = ("core_functions", "node_transport", "app_functions", "execution_engine", "robot_bridges", "cell_runner", "operator_station")
TESTS = "test"
#: A function-level import says why it is not at the top: the library is optional or slow to load.
REASON = re.compile(r"\b(optional|slow)\b", re.IGNORECASE)
#: The only project modules imported inside functions: each loads, when imported, a library that is optional (a
#: pip extra) or slow to load, so the code that needs it imports it when it runs.  Module -> that library
#: (checked: the module's own module-level imports, followed through the project, load it).
HEAVY_MODULES = {
    "operator_station.server": "starlette",  # optional: pip extra 'studio'
    "operator_station.serving": "uvicorn",  # optional: pip extra 'studio'
    "node_transport.link_transforms": "pinocchio",  # slow to load (0.1 s): the recorder's encoder, bridges without a URDF
    "execution_engine.timeline_plot": "matplotlib",  # slow to load (0.4 s): report draws only when asked
    # The subcommands that need the back ends, the simulators or the camera, imported when they run so that
    # validate, functions and report start without numpy, pinocchio, coal and OpenCV (test_fast_start.py):
    "cell_runner.run_command": "numpy",  # run: back ends, simulators, dry run (numpy, pinocchio, coal: 0.5 s)
    "cell_runner.dry_run.check": "numpy",  # validate --simulate: the dry run (numpy, pinocchio, coal)
    "cell_runner.vision_detect": "cv2",  # vision detect: OpenCV (0.2 s)
    "cell_runner.camera_sim": "numpy",  # camera-sim: the renderer and the URDF model (numpy, OpenCV, pinocchio)
    "cell_runner.run_report": "mcap",  # report: the recording's reader and its ROS 2 decoder (0.05 s)
    "robot_bridges.kuka_rsi.backend": "numpy",  # a KUKA dry run's clock: the RSI back end (0.05 s) left out of other runs
    "operator_station.cli": "numpy",  # studio: sessions, simulators, dry run (numpy, pinocchio, coal)
}


@dataclass(frozen=True)
class Import:
    """One module (or one name of a module) that a file imports."""

    file: str  # the importing file, relative to the root (posix)
    line: int
    module: str  # dotted, absolute: the module loaded (for ``from m import sub``, ``m.sub`` when that is a submodule)
    name: str | None  # the name taken from ``module`` (``from m import name``); None when the module itself is bound
    target: str | None  # the project file ``module`` is, None outside the project
    in_function: bool  # runs when the function is called, not when the file loads
    type_checking: bool  # under ``if TYPE_CHECKING:``
    comment: str  # the comments on the statement's lines and the line before it (or before its run of imports); '' if none


@dataclass(frozen=True)
class PrivateUse:
    """An underscore name of another project module reached through the module: ``codec._plan``."""

    file: str
    line: int
    module: str
    name: str


@dataclass(frozen=True)
class Project:
    """Where the project's modules are: packages under ``root`` and a folder of top-level modules."""

    root: Path = ROOT
    packages: tuple[str, ...] = PACKAGES
    tests: str = TESTS

    def modules(self) -> dict[str, str]:
        """Every module's dotted name -> its file (relative, posix)."""
        names: dict[str, str] = {}
        for package in self.packages:
            for path in sorted((self.root / package).rglob("*.py")):
                rel = path.relative_to(self.root)
                parts = list(rel.with_suffix("").parts)
                if parts[-1] == "__init__":
                    parts.pop()
                names[".".join(parts)] = rel.as_posix()
        for path in sorted((self.root / self.tests).glob("*.py")):
            names[path.stem] = path.relative_to(self.root).as_posix()
        return names


def _comments(text: str) -> dict[int, str]:
    """Line number -> the comment on it."""
    found: dict[int, str] = {}
    for token in tokenize.generate_tokens(io.StringIO(text).readline):
        if token.type == tokenize.COMMENT:
            found[token.start[0]] = token.string.lstrip("#").strip()
    return found


def _runs_of_imports(tree: ast.AST) -> dict[int, int]:
    """Line of each import statement -> the first line of the run of imports it is in (one statement after
    another in the same block): a comment above the run speaks for all of it."""
    first: dict[int, int] = {}
    for node in ast.walk(tree):
        for field in ("body", "orelse", "finalbody", "handlers"):
            statements = getattr(node, field, None)
            if not isinstance(statements, list):
                continue
            start: int | None = None
            for statement in statements:
                if isinstance(statement, (ast.Import, ast.ImportFrom)):
                    start = statement.lineno if start is None else start
                    first[statement.lineno] = start
                else:
                    start = None
    return first


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def private(name: str) -> bool:
    """An underscore name, not a dunder (``__version__``, ``__main__``)."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


class _Visitor(ast.NodeVisitor):
    def __init__(self, rel: str, name: str, modules: dict[str, str], comments: dict[int, str], runs: dict[int, int]) -> None:
        self.rel = rel
        self.runs = runs
        self.package = name if rel.endswith("/__init__.py") else name.rpartition(".")[0]
        self.modules = modules
        self.comments = comments
        self.found: list[Import] = []
        self.bound: dict[str, str] = {}  # local name -> the project module it is bound to
        self.private_uses: list[PrivateUse] = []
        self._functions = 0
        self._type_checking = 0

    def _function(self, node: ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) -> None:
        self._functions += 1
        self.generic_visit(node)
        self._functions -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = visit_Lambda = _function

    def visit_If(self, node: ast.If) -> None:
        if not _is_type_checking(node.test):
            self.generic_visit(node)
            return
        self._type_checking += 1
        for statement in node.body:
            self.visit(statement)
        self._type_checking -= 1
        for statement in node.orelse:
            self.visit(statement)

    def _add(self, node: ast.Import | ast.ImportFrom, module: str, name: str | None) -> None:
        lines = range(self.runs.get(node.lineno, node.lineno) - 1, (node.end_lineno or node.lineno) + 1)
        comment = " ".join(self.comments[n] for n in lines if n in self.comments)
        self.found.append(
            Import(self.rel, node.lineno, module, name, self.modules.get(module), self._functions > 0, self._type_checking > 0, comment)
        )

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self._add(node, alias.name, None)
            if alias.asname:
                self.bound[alias.asname] = alias.name
            else:
                top = alias.name.partition(".")[0]
                self.bound[top] = top

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level:
            parts = self.package.split(".")
            base = ".".join(parts[: len(parts) - node.level + 1])
            module = f"{base}.{node.module}" if node.module else base
        else:
            module = node.module or ""
        for alias in node.names:
            submodule = f"{module}.{alias.name}"
            if submodule in self.modules:
                self._add(node, submodule, None)
                self.bound[alias.asname or alias.name] = submodule
            else:
                self._add(node, module, alias.name)

    def _module_of(self, node: ast.expr) -> str | None:
        """The project module an expression such as ``codec`` or ``node_transport.codec`` names."""
        if isinstance(node, ast.Name):
            dotted = self.bound.get(node.id)
        elif isinstance(node, ast.Attribute):
            outer = self._module_of(node.value)
            dotted = f"{outer}.{node.attr}" if outer is not None else None
        else:
            return None
        return dotted if dotted is not None and (dotted in self.modules or any(m.startswith(dotted + ".") for m in self.modules)) else None

    def _private_use(self, node: ast.AST, module: str | None, name: str) -> None:
        if module is not None and module in self.modules and self.modules[module] != self.rel and private(name):
            self.private_uses.append(PrivateUse(self.rel, getattr(node, "lineno", 0), module, name))

    def visit_Attribute(self, node: ast.Attribute) -> None:
        self._private_use(node, self._module_of(node.value), node.attr)
        self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        """``getattr(module, "_x")``, ``monkeypatch.setattr(module, "_x", ...)``, ``monkeypatch.setattr("m._x", ...)``."""
        func = node.func
        called = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
        if called in ("getattr", "setattr", "delattr", "hasattr") and node.args:
            first = node.args[0]
            second = node.args[1] if len(node.args) > 1 else None
            if isinstance(second, ast.Constant) and isinstance(second.value, str):
                self._private_use(node, self._module_of(first), second.value)
            elif isinstance(first, ast.Constant) and isinstance(first.value, str):  # monkeypatch's "pkg.module.name"
                module, _, name = first.value.rpartition(".")
                self._private_use(node, module, name)
        self.generic_visit(node)


@dataclass
class Walk:
    """Everything the rules look at, for every file of the project."""

    modules: dict[str, str]
    imports: list[Import]
    private_uses: list[PrivateUse]

    @property
    def files(self) -> list[str]:
        return sorted(set(self.modules.values()))


def walk(project: Project = Project()) -> Walk:
    modules = project.modules()
    imports: list[Import] = []
    uses: list[PrivateUse] = []
    for name, rel in sorted(modules.items(), key=lambda kv: kv[1]):
        text = (project.root / rel).read_text(encoding="utf-8")
        tree = ast.parse(text, filename=rel)
        visitor = _Visitor(rel, name, modules, _comments(text), _runs_of_imports(tree))
        visitor.visit(tree)
        imports += visitor.found
        uses += visitor.private_uses
    return Walk(modules, imports, uses)


def graph(imports: Iterable[Import]) -> dict[str, set[str]]:
    """File -> the project files it imports (itself left out)."""
    edges: dict[str, set[str]] = {}
    for i in imports:
        edges.setdefault(i.file, set())
        if i.target is not None and i.target != i.file:
            edges[i.file].add(i.target)
            edges.setdefault(i.target, set())
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one file (each holds every cycle through its files), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in sorted(edges):
        if start in index:
            continue
        # Tarjan's algorithm without recursion (a long chain of imports must not reach the recursion limit)
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        work: list[tuple[str, list[str]]] = [(start, sorted(edges[start]))]
        while work:
            node, todo = work[-1]
            if todo:
                nxt = todo.pop(0)
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, sorted(edges.get(nxt, ()))))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def private_imports(found: Walk) -> list[Import]:
    """Imports of another module's underscore names (``from m import _x``), or of a private module (``m/_x.py``)
    from outside its package.  A public name a package's ``__init__`` re-exports is public."""
    result = []
    for i in found.imports:
        if i.target is None or i.target == i.file:
            continue
        if i.name is not None and private(i.name):
            result.append(i)
        elif i.name is None and private(i.module.rpartition(".")[2]):
            owner = found.modules.get(i.module.rpartition(".")[0])
            if owner is None or Path(owner).parent != Path(i.file).parent:
                result.append(i)
    return result


def function_level(imports: Iterable[Import]) -> list[Import]:
    return [i for i in imports if i.in_function]


def unexplained(imports: Iterable[Import]) -> list[Import]:
    """Function-level imports without a comment (on their lines, the line before, or above their run of
    imports) saying optional or slow."""
    return [i for i in function_level(imports) if not REASON.search(i.comment)]


def project_modules_in_functions(imports: Iterable[Import], heavy: dict[str, str] = HEAVY_MODULES) -> list[Import]:
    """Function-level imports of the project's own modules, but for the few that load a heavy library."""
    return [i for i in function_level(imports) if i.target is not None and i.module not in heavy]


def loads_at_import(found: Walk, module: str) -> set[str]:
    """The top-level names of the libraries importing ``module`` loads: its module-level imports outside
    ``TYPE_CHECKING``, followed through the project's own modules."""
    seen: set[str] = set()
    libraries: set[str] = set()
    todo = [found.modules[module]]
    by_file: dict[str, list[Import]] = {}
    for i in found.imports:
        if not i.in_function and not i.type_checking:
            by_file.setdefault(i.file, []).append(i)
    while todo:
        rel = todo.pop()
        if rel in seen:
            continue
        seen.add(rel)
        for i in by_file.get(rel, ()):
            if i.target is not None:
                todo.append(i.target)
            elif i.module:
                libraries.add(i.module.partition(".")[0])
    return libraries - set(sys.stdlib_module_names)


def describe(i: Import) -> str:
    what = f"{i.module}:{i.name}" if i.name else i.module
    flags = "".join((" [in function]" if i.in_function else "", " [TYPE_CHECKING]" if i.type_checking else ""))
    comment = f"  # {i.comment}" if i.comment else ""
    return f"{i.file}:{i.line}: {what}{flags}{comment}"


def report(project: Project = Project()) -> str:
    """Every file's project imports, the cycles, private names taken and function-level imports, as text."""
    found = walk(project)
    out: list[str] = ["# project imports per file"]
    for rel in found.files:
        own = [i for i in found.imports if i.file == rel and i.target is not None]
        if own:
            out.append(rel)
            out += [f"    {describe(i).partition(': ')[2]}  -> {i.target}" for i in own]
    out.append("\n# cycles (strongly connected components) and the imports inside each")
    for component in cycles(graph(found.imports)):
        members = set(component)
        out.append("  " + " <-> ".join(component))
        out += [f"      {describe(i)}" for i in found.imports if i.file in members and i.target in members and i.target != i.file]
    out.append("\n# private names of another module")
    out += ["  " + describe(i) for i in private_imports(found)]
    out += [f"  {u.file}:{u.line}: {u.module}.{u.name}" for u in found.private_uses]
    out.append("\n# function-level imports (! breaks the rule: a project module, or no comment saying optional or slow)")
    bad = set(unexplained(found.imports)) | set(project_modules_in_functions(found.imports))
    out += [("! " if i in bad else "  ") + describe(i) for i in function_level(found.imports)]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.stdout.write(report())
