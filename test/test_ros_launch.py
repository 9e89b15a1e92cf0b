"""The launch file and its parameter file agree with the code they start.

The launch file is read with ``ast`` (it must name only executables setup.py installs) and run
against small stand-ins of ``launch`` / ``launch_ros`` to check its wiring.  The YAML is compared
with the parameters the nodes really declare, by building those nodes on the local transport.
"""
from __future__ import annotations

import ast
import importlib.util
import sys
import types
from pathlib import Path
from typing import Any

import pytest
import yaml
from scripted_backend import ScriptedBackend

from core_functions.robots import NEXTAGE_OPEN
from execution_engine.clock import Clock
from execution_engine.deployment import deploy_local
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.machine.group_machine import GroupMachine
from execution_engine.nodes import declare_engine_parameters
from execution_engine.ros_main import ENGINE_NODE, bridge_node_name, machine_node_name
from execution_engine.transport.local import LocalTransport
from execution_engine.transport.port import Node
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.nextage_sim.node import BACKEND, declare_nextage_parameters
from robot_bridges.registry import create_backend

ROOT = Path(__file__).resolve().parent.parent
LAUNCH = ROOT / "launch" / "nextage_sim.launch.py"
CONFIG = ROOT / "config" / "nextage_sim.yaml"
SHARE = "/opt/ws/install/dual_arm_executive/share/dual_arm_executive"
EXPECTED_NODES = {bridge_node_name(BACKEND), *(machine_node_name(g) for g in NEXTAGE_OPEN.group_names), ENGINE_NODE}
SET_BY_LAUNCH = {ENGINE_NODE: {"application"}, bridge_node_name(BACKEND): {"speed"}}


@pytest.fixture(autouse=True)
def private_data_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))


def console_scripts() -> set[str]:
    tree = ast.parse((ROOT / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == "console_scripts":
                    return {ast.literal_eval(item).split("=")[0].strip() for item in value.elts}  # type: ignore[attr-defined]
    raise AssertionError("setup.py declares no console_scripts")


def config() -> dict[str, dict[str, Any]]:
    data = yaml.safe_load(CONFIG.read_text())
    return {name: section["ros__parameters"] for name, section in data.items()}


# ================================================================================= launch file
def test_the_launch_file_names_only_installed_executables() -> None:
    tree = ast.parse(LAUNCH.read_text(), filename=str(LAUNCH))
    executables = {
        keyword.value.value
        for call in ast.walk(tree)
        if isinstance(call, ast.Call)
        for keyword in call.keywords
        if keyword.arg == "executable" and isinstance(keyword.value, ast.Constant)
    }
    assert executables == {"nextage_sim_bridge", "group_machine", "execution_engine"}
    assert executables <= console_scripts()


class _Recorded:
    """Stand-in for a launch action or substitution: remembers how it was made."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs


def _launch_modules() -> dict[str, types.ModuleType]:
    def module(name: str, **attributes: Any) -> types.ModuleType:
        made = types.ModuleType(name)
        made.__dict__.update(attributes)
        return made

    def share_directory(package: str) -> str:
        assert package == "dual_arm_executive"
        return SHARE

    classes = {name: type(name, (_Recorded,), {}) for name in ("LaunchDescription", "DeclareLaunchArgument", "LaunchConfiguration", "Node", "ParameterValue")}
    return {
        "launch": module("launch", LaunchDescription=classes["LaunchDescription"]),
        "launch.actions": module("launch.actions", DeclareLaunchArgument=classes["DeclareLaunchArgument"]),
        "launch.substitutions": module("launch.substitutions", LaunchConfiguration=classes["LaunchConfiguration"]),
        "launch_ros": module("launch_ros"),
        "launch_ros.actions": module("launch_ros.actions", Node=classes["Node"]),
        "launch_ros.parameter_descriptions": module("launch_ros.parameter_descriptions", ParameterValue=classes["ParameterValue"]),
        "ament_index_python": module("ament_index_python"),
        "ament_index_python.packages": module("ament_index_python.packages", get_package_share_directory=share_directory),
    }


def generated_description(monkeypatch: pytest.MonkeyPatch) -> Any:
    for name, module in _launch_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location("nextage_sim_launch", LAUNCH)
    assert spec is not None and spec.loader is not None
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    return launch_file.generate_launch_description()


def test_the_launch_file_starts_the_cell_with_its_parameters(monkeypatch: pytest.MonkeyPatch) -> None:
    actions = generated_description(monkeypatch).args[0]
    arguments = {a.args[0]: a.kwargs for a in actions if type(a).__name__ == "DeclareLaunchArgument"}
    assert arguments["application"]["default_value"] == f"{SHARE}/apps_xml/rivet_installation.xml"
    assert arguments["speed"]["default_value"] == "1.0"
    started = {a.kwargs["name"]: a.kwargs for a in actions if type(a).__name__ == "Node"}
    assert set(started) == EXPECTED_NODES
    sections = config()
    for name, node in started.items():
        assert node["package"] == "dual_arm_executive"
        config_file, *overrides = node["parameters"]
        assert config_file == f"{SHARE}/config/nextage_sim.yaml" and name in sections
        for given in overrides:
            for key, value in given.items():
                assert key in sections[name]
                if type(value).__name__ == "ParameterValue":  # a launch argument, typed like the YAML value
                    assert value.args[0].args == (key,) and value.kwargs["value_type"] is type(sections[name][key])
                else:
                    assert value == sections[name][key]
    for group in NEXTAGE_OPEN.group_names:
        assert started[machine_node_name(group)]["parameters"][1] == {"group": group}


def test_ros_node_names_are_the_embedded_deployments(run_sim: Any) -> None:
    async def main(clock: Clock) -> list[str]:
        transport = LocalTransport(clock)
        deployment = await deploy_local(clock, NEXTAGE_OPEN, ScriptedBackend(clock, NEXTAGE_OPEN, {}), transport=transport)
        try:
            return transport.node_names()
        finally:
            await deployment.close()

    names = set(run_sim(main))
    assert {f"/{n}" for n in EXPECTED_NODES - {bridge_node_name(BACKEND)}} <= names


# ================================================================================= config file
async def _declared(clock: Clock, name: str, overrides: dict[str, Any] | None = None) -> Node:
    """A node of ``name`` with every parameter its entry point declares."""
    node = LocalTransport(clock).create_node(name, parameters=overrides)
    if name == ENGINE_NODE:
        declare_engine_parameters(node)
        ExecutionEngine(node)
    elif name == bridge_node_name(BACKEND):
        setup = declare_nextage_parameters(node)
        backend = await create_backend(BACKEND, clock, setup.options)
        BridgeNode(node, backend)
    else:
        GroupMachine(node).close()
    return node


@pytest.mark.parametrize("name", sorted(EXPECTED_NODES))
def test_the_config_lists_every_declared_parameter_with_its_default(name: str, run_sim: Any) -> None:
    section = config()[name]
    group = {"group": section["group"]} if "group" in section else None
    declared = run_sim(lambda clock: _declared(clock, name, group)).declared_parameters()
    assert set(section) == set(declared)
    for key, value in section.items():
        assert type(value) is type(declared[key]), f"{name}.{key}: YAML {value!r} is not a {type(declared[key]).__name__}"
        if key not in SET_BY_LAUNCH.get(name, set()):
            assert value == declared[key], f"{name}.{key}: YAML says {value!r}, the code's default is {declared[key]!r}"


@pytest.mark.parametrize("name", sorted(EXPECTED_NODES))
def test_the_config_loads_as_overrides_without_a_stray_key(name: str, run_sim: Any) -> None:
    node = run_sim(lambda clock: _declared(clock, name, config()[name]))
    assert node.undeclared_overrides() == []


def test_the_config_has_a_section_for_each_started_node_only() -> None:
    assert set(config()) == EXPECTED_NODES
