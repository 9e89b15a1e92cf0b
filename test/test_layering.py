"""The import rules of docs/architecture.md, checked on the source: the core never needs ROS 2."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("execution_engine", "core_functions", "node_transport", "app_functions", "robot_bridges", "operator_station")
# Wiring may import back ends; nothing else may.
WIRING = {"execution_engine/cli.py", "execution_engine/deployment.py", "execution_engine/nodes.py", "execution_engine/ros_main.py"}
# The command line's settings name the back end's options (docs/architecture.md).
WIRING |= {"execution_engine/settings.py"}
# The dry run builds a robot's simulator and wraps its back end (docs/application_xml.md, "Checking before anything moves").
WIRING |= {f"execution_engine/dry_run/{m}.py" for m in ("backend", "check", "runner", "simulators", "collisions", "placement", "cell_start")}
# The operator station runs the engine and a back end in-process (docs/studio.md): wiring too.
WIRING |= {"operator_station/session.py"}
ROS_ADAPTERS = {"node_transport/ros.py"}


def imports() -> list[tuple[str, str]]:
    found = []
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Import):
                    found += [(rel, alias.name) for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                    found.append((rel, node.module))
    return found


IMPORTS = imports()


def test_only_the_ros_adapter_imports_rclpy() -> None:
    offenders = [(f, m) for f, m in IMPORTS if m.split(".")[0] in ("rclpy", "launch", "launch_ros") and f not in ROS_ADAPTERS and not f.endswith("/node.py")]
    assert offenders == []


@pytest.mark.parametrize(
    ("package", "allowed"),
    [
        ("core_functions", {"core_functions"}),
        ("app_functions", {"core_functions", "app_functions"}),
    ],
)
def test_lower_layers_do_not_import_upper_ones(package: str, allowed: set[str]) -> None:
    project = set(PACKAGES)
    offenders = [(f, m) for f, m in IMPORTS if f.startswith(package + "/") and m.split(".")[0] in project and m.split(".")[0] not in allowed]
    assert offenders == []


def test_bridges_use_only_the_transport_port_and_the_clock_of_the_engine() -> None:
    offenders = [
        (f, m)
        for f, m in IMPORTS
        if f.startswith("robot_bridges/")
        and m.startswith("execution_engine")
        and not (m.startswith("node_transport") or m == "node_transport.clock")
        and not f.endswith("/node.py")
        and not (m.startswith("execution_engine.app_model") and f.endswith("/node.py"))
    ]
    assert offenders == []


def test_nothing_but_wiring_imports_robot_bridges() -> None:
    offenders = [(f, m) for f, m in IMPORTS if m.startswith("robot_bridges") and not f.startswith("robot_bridges/") and f not in WIRING]
    assert offenders == []


def test_only_the_cli_reaches_up_to_the_operator_station() -> None:
    """The station sits on top of everything; below it only the command line's one hook names it."""
    offenders = [(f, m) for f, m in IMPORTS if m.startswith("operator_station") and not f.startswith("operator_station/") and f != "execution_engine/cli.py"]
    assert offenders == []
