"""The import walk itself (``import_graph.py``), on small trees of its own: what it counts as an import, a cycle,
a private name and a function-level import with its reason.  The rules it serves are held on the project's
source by ``test_layering.py``.
"""
from __future__ import annotations

from pathlib import Path

from import_graph import (
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

# ------------------------------------------------------------------ the walk on a tree of its own
def _tree(root: Path, files: dict[str, str]) -> Walk:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text, encoding="utf-8")
    return walk(Project(root, ("app",), "tests"))


def test_the_walk_resolves_relative_submodule_and_type_checking_imports_into_cycles(tmp_path: Path) -> None:
    found = _tree(tmp_path, {
        "app/__init__.py": "from .engine import Engine\n",
        "app/engine.py": "from . import flags\nclass Engine: ...\n",
        "app/flags.py": (
            "from typing import TYPE_CHECKING\n"
            "if TYPE_CHECKING:\n    from app.engine import Engine\n"
        ),
        "app/sub/__init__.py": "",
        "app/sub/deep.py": "from ..report import summary\nfrom app import Engine\n",
        "app/report.py": "def summary():\n    # slow to load: only when asked\n    from app.sub import deep\n",
        "tests/helper.py": "import app.flags\n",
        "tests/test_x.py": "import helper\n",
    })
    edges = graph(found.imports)
    assert edges["app/engine.py"] == {"app/flags.py"}  # from . import flags: the submodule's file
    assert edges["app/flags.py"] == {"app/engine.py"}  # a type-only import is an edge
    assert edges["app/sub/deep.py"] == {"app/report.py", "app/__init__.py"}
    assert edges["tests/test_x.py"] == {"tests/helper.py"}  # test/ holds top-level modules
    assert cycles(edges) == [
        ["app/engine.py", "app/flags.py"],  # the __init__ that imports engine is outside: nothing imports it back
        ["app/report.py", "app/sub/deep.py"],  # a function-level import closes a cycle too
    ]
    assert [describe(i) for i in project_modules_in_functions(found.imports, heavy={})] == [
        "app/report.py:3: app.sub.deep [in function]  # slow to load: only when asked"
    ]


def test_the_walk_finds_private_names_imported_or_reached_through_a_module(tmp_path: Path) -> None:
    found = _tree(tmp_path, {
        "app/__init__.py": "from app.codec import encode\n",
        "app/codec.py": "_plan = 1\ndef encode(): return _plan\n__version__ = '1'\n",
        "app/_impl.py": "",
        "app/schema.py": "from app.codec import _plan, __version__\nfrom app import _impl, encode\n",
        "other/__init__.py": "",
        "tests/test_codec.py": (
            "from app import codec\nimport app.codec as c\n"
            "def test(monkeypatch):\n"
            "    codec._plan\n    getattr(c, '_plan')\n    monkeypatch.setattr('app.codec._plan', 2)\n    codec.encode()\n"
            "    from app import _impl  # optional: nothing\n"
        ),
    })
    assert [(i.file, i.module, i.name) for i in private_imports(found)] == [
        ("app/schema.py", "app.codec", "_plan"),  # a dunder is no private name; a sibling private module is the package's own
        ("tests/test_codec.py", "app._impl", None),
    ]
    assert [(u.file, u.line, u.module, u.name) for u in found.private_uses] == [
        ("tests/test_codec.py", 4, "app.codec", "_plan"),
        ("tests/test_codec.py", 5, "app.codec", "_plan"),
        ("tests/test_codec.py", 6, "app.codec", "_plan"),
    ]


def test_a_function_level_import_needs_its_reason_in_a_comment(tmp_path: Path) -> None:
    found = _tree(tmp_path, {
        "app/__init__.py": (
            "def a():\n    import cv2  # optional: pip extra 'vision'\n"
            "def b():\n    # pinocchio is slow to load\n    import pinocchio\n"
            "def c():\n    import json\n"
            "def d():\n    from matplotlib import (  # noqa: E402\n        pyplot,\n    )\n"
            "def e():\n    # optional: selenium, to drive a browser\n    from selenium import webdriver\n    import selenium.common\n"
            "    x = 1\n    import selenium.webdriver.chrome\n"
            "try:\n    import yaml\nexcept ImportError:\n    yaml = None\n"
        ),
    })
    assert [i.module for i in function_level(found.imports)] == [
        "cv2", "pinocchio", "json", "matplotlib", "selenium", "selenium.common", "selenium.webdriver.chrome",
    ]
    # a comment above a run of imports speaks for the run, not for an import after other code
    assert [i.module for i in unexplained(found.imports)] == ["json", "matplotlib", "selenium.webdriver.chrome"]


def test_loads_at_import_follows_module_level_imports_only(tmp_path: Path) -> None:
    found = _tree(tmp_path, {
        "app/__init__.py": "",
        "app/server.py": "import json\nfrom app import pages\ndef later():\n    import uvicorn  # optional\n",
        "app/pages.py": "from typing import TYPE_CHECKING\nimport starlette.responses\nif TYPE_CHECKING:\n    import numpy\n",
    })
    assert loads_at_import(found, "app.server") == {"starlette"}
