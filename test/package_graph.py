"""The picture of the packages and their arrows that opens docs/architecture.md, drawn from the imports.

A hand-drawn diagram drifts the day someone adds an import; this one is the import walk of
``import_graph.py`` folded to packages: one box per package (what it holds), one arrow per pair of
packages that the code has, with the number of imports along it (an import is one file importing one
project module, however many names it takes).  Program entries (``__main__.py``) are left out: they
compose every layer and nothing imports them.  ``test_layering.py`` checks that the block in
docs/architecture.md is what this script draws now.

    .venv/bin/python test/package_graph.py                              # print the Mermaid block
    .venv/bin/python test/package_graph.py --write docs/architecture.md  # replace the block there
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from import_graph import PACKAGES, Walk, walk

#: The order the boxes are drawn in, bottom layer last, so the arrows point down the page.
LAYERS = (("operator_station",), ("cell_runner",), ("app_functions", "execution_engine", "robot_bridges"), ("node_transport",), ("core_functions",))
#: What each box says the package holds.
ROLES = {
    "operator_station": "the browser's operator station",
    "cell_runner": "the wiring: command line, deployment, node processes, dry run",
    "app_functions": "function libraries (skills)",
    "execution_engine": "application model, engine, group machines, recorder",
    "robot_bridges": "bridges, back ends, simulators",
    "node_transport": "transport port, transports, messages, clock",
    "core_functions": "robot API, robots, geometry, catalog",
}
BEGIN = "<!-- package graph: drawn by test/package_graph.py from the imports; do not edit by hand -->"
END = "<!-- end of package graph -->"


def package_of(file: str) -> str | None:
    """The project package ``file`` belongs to, None for tests and anything else."""
    top = file.split("/", 1)[0]
    return top if top in PACKAGES and "/" in file else None


def is_entry(file: str) -> bool:
    """A program entry (``__main__.py``): it composes the layers, nothing imports it."""
    return file.endswith("/__main__.py")


def arrows(found: Walk) -> Counter[tuple[str, str]]:
    """(importing package, imported package) -> how many imports run along that arrow."""
    pairs = {
        (i.file, i.target) for i in found.imports
        if i.target is not None and not is_entry(i.file) and package_of(i.file) and package_of(i.target)
    }
    return Counter(
        (package_of(a), package_of(b)) for a, b in pairs if package_of(a) != package_of(b)  # type: ignore[misc]
    )


def mermaid(found: Walk) -> str:
    """The Mermaid block (fenced, between the markers) for ``found``."""
    lines = [BEGIN, "```mermaid", "flowchart TD"]
    for layer in LAYERS:
        lines += [f'    {package}["<b>{package}</b><br/>{ROLES[package]}"]' for package in layer]
    order = {p: n for n, p in enumerate(p for layer in LAYERS for p in layer)}
    for (a, b), n in sorted(arrows(found).items(), key=lambda kv: (order[kv[0][0]], order[kv[0][1]])):
        lines.append(f"    {a} -->|{n}| {b}")
    lines += ["```", END]
    return "\n".join(lines) + "\n"


def block_in(text: str) -> str | None:
    """The drawn block in a document's text (markers included), None if it has none."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        return None
    return text[start:end + len(END)] + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="test/package_graph.py", description=__doc__.splitlines()[0])
    parser.add_argument("--write", metavar="MARKDOWN", type=Path, help="replace the block between the markers in this file")
    args = parser.parse_args(argv)
    drawn = mermaid(walk())
    if args.write is None:
        sys.stdout.write(drawn)
        return 0
    text = args.write.read_text(encoding="utf-8")
    old = block_in(text)
    if old is None:
        print(f"error: {args.write}: no package graph markers ({BEGIN!r} ... {END!r}) to replace", file=sys.stderr)
        return 2
    args.write.write_text(text.replace(old, drawn, 1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
