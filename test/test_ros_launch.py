"""The launch files and their parameter files agree with the code they start.

Each launch file (Nextage simulator, V+, KUKA RSI) is run the way ``ros2 launch`` runs it, against the model of
``launch`` / ``launch_ros`` (jazzy: launch 3.4, launch_ros 0.26) in ``launch_fakes.py``, so the tests see each
node's namespace, parameters (resolved as rclpy resolves them) and command line.  The YAML files are compared with
the parameters the nodes really declare, by building those nodes on the local transport.
"""
from __future__ import annotations

import ast
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.machinery import SourceFileLoader
from importlib.util import module_from_spec, spec_from_loader
from pathlib import Path
from typing import Any

import pytest
import yaml
from launch_fakes import (
    ROOT,
    SHARE,
    DeclareLaunchArgument,
    GroupAction,
    LaunchConfiguration,
    LaunchContext,
    LaunchDescription,
    LaunchNode,
    ParameterValue,
    PushRosNamespace,
    StartedNode,
    fake_launch,  # noqa: F401 - fixture
    prefix_namespace,
    rclpy_section_matches,
    visit,
)
from ros_fakes import fake_rclpy  # noqa: F401 - fixture
from scripted_backend import ScriptedBackend
from test_ros_transport import run_real

from cell_runner.bridge_nodes.common import BridgeSetup
from cell_runner.bridge_nodes.kuka_rsi import BACKEND as KUKA_RSI, declare_kuka_parameters
from cell_runner.bridge_nodes.nextage_sim import BACKEND as NEXTAGE_SIM, declare_nextage_parameters
from cell_runner.bridge_nodes.vplus import BACKEND as VPLUS, declare_vplus_parameters
from cell_runner.deployment import deploy_local
from cell_runner.libraries import APPLICATION_FUNCTIONS
from cell_runner.nodes import declare_engine_parameters
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN, RobotModel
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.machine.group_machine import GroupMachine
from node_transport.clock import Clock, FollowingClock
from node_transport.local import LocalTransport
from node_transport.port import Node
from node_transport.ros import RosTransport
from node_transport.ros_convert import RCLPY_OWN_PARAMETERS
from node_transport.wire import ENGINE_NODE, bridge_node_name, machine_node_name
from robot_bridges.bridge_node import BridgeNode



@dataclass(frozen=True)
class Cell:
    """One launch file and what it must start."""

    name: str  # launch/<name>.launch.py, config/<name>.yaml
    backend: str  # registry name of the bridge's back end
    robot: RobotModel
    declare: Callable[[Node], BridgeSetup]
    application: str  # the default application, in apps_xml/
    #: the back end's own launch arguments: argument -> (bridge parameter it sets, its type)
    arguments: dict[str, tuple[str, type]] = field(default_factory=dict)

    @property
    def launch(self) -> Path:
        return ROOT / "launch" / f"{self.name}.launch.py"

    @property
    def config(self) -> Path:
        return ROOT / "config" / f"{self.name}.yaml"

    @property
    def bridge(self) -> str:
        return bridge_node_name(self.backend)

    @property
    def nodes(self) -> set[str]:
        return {self.bridge, *(machine_node_name(g) for g in self.robot.group_names), ENGINE_NODE}

    def set_by_launch(self) -> dict[str, dict[str, Any]]:
        """node -> parameter -> the value the launch file gives it when no argument is passed."""
        sections = config(self)
        given: dict[str, dict[str, Any]] = {ENGINE_NODE: {"application": f"{SHARE}/apps_xml/{self.application}"}}
        given[self.bridge] = {parameter: sections[self.bridge][parameter] for parameter, _ in self.arguments.values()}
        for group in self.robot.group_names:
            given[machine_node_name(group)] = {"group": group, "robot": self.robot.name}
        return given


CELLS = [
    Cell("nextage_sim", NEXTAGE_SIM, NEXTAGE_OPEN, declare_nextage_parameters, "rivet_installation.xml", {"speed": ("speed", float)}),
    Cell("vplus", VPLUS, ADEPT_VIPER_S850, declare_vplus_parameters, "vplus_pick_inspect.xml", {"host": ("host", str), "port": ("port", int)}),
    Cell(
        "kuka_rsi",
        KUKA_RSI,
        KUKA_KR,
        declare_kuka_parameters,
        "kuka_rsi_demo.xml",
        {"rsi_listen": ("rsi_listen", str), "host": ("host", str), "rsi_config": ("config", str), "cycle": ("cycle", int), "mode": ("mode", str)},
    ),
]
CELL_IDS = [cell.name for cell in CELLS]
NODES = [(cell, name) for cell in CELLS for name in sorted(cell.nodes)]
NODE_IDS = [f"{cell.name}:{name}" for cell, name in NODES]
ROS_ARGUMENTS = {"namespace": "", "use_sim_time": "false", "log_level": "info"}


@pytest.fixture(autouse=True)
def private_data_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))


def config(cell: Cell) -> dict[str, dict[str, Any]]:
    """The node sections of the cell's YAML by node name (keys are ``/**/<node>``)."""
    data = yaml.safe_load(cell.config.read_text())
    return {key.removeprefix("/**/"): section["ros__parameters"] for key, section in data.items()}


def description(cell: Cell) -> LaunchDescription:
    """``generate_launch_description()`` of the cell's launch file, loaded as ros2 launch loads it."""
    loader = SourceFileLoader("python_launch_file", str(cell.launch))
    spec = spec_from_loader(loader.name, loader)
    assert spec is not None
    launch_file = module_from_spec(spec)
    loader.exec_module(launch_file)
    made = launch_file.generate_launch_description()
    assert isinstance(made, LaunchDescription)
    return made


def declared_arguments(cell: Cell) -> dict[str, DeclareLaunchArgument]:
    return {a.name: a for a in description(cell).entities if isinstance(a, DeclareLaunchArgument)}


def launch(cell: Cell, **arguments: str) -> dict[str, StartedNode]:
    """``ros2 launch dual_arm_executive <cell>.launch.py name:=value ...``: the nodes it starts, by name."""
    context = LaunchContext(arguments)
    visit(context, description(cell).entities)
    started = {node.name: node for node in context.processes}
    assert len(started) == len(context.processes), "two nodes of one name"
    return started


# ============================================================================ the model itself
def test_the_launch_model_resolves_namespaces_as_launch_ros_does() -> None:
    assert prefix_namespace("my_ns", "original_ns") == "my_ns/original_ns"  # launch_ros' own examples
    assert prefix_namespace("/my_ns", "original_ns") == "/my_ns/original_ns"
    assert prefix_namespace("my_ns", "/original_ns") == "/original_ns"
    assert prefix_namespace(None, "original_ns") == "original_ns"
    assert prefix_namespace("my_ns", None) == "my_ns"
    context = LaunchContext({"ns": "cell_a"})
    inner = LaunchNode(executable="x", name="n", namespace="arm")
    visit(context, [LaunchNode(executable="x", name="root", namespace=""), GroupAction([PushRosNamespace(LaunchConfiguration("ns")), inner])])
    visit(context, [LaunchNode(executable="x", name="after")])
    assert [(n.name, n.namespace) for n in context.processes] == [("root", "/"), ("n", "/cell_a/arm"), ("after", "/")]
    with pytest.raises(TypeError):
        LaunchNode(executable="x", node_namespace="old_keyword")


def test_the_launch_model_types_parameters_as_launch_ros_does() -> None:
    context = LaunchContext({"a": "off"})
    node = LaunchNode(executable="x", name="n", parameters=[{"raw": LaunchConfiguration("a"), "typed": ParameterValue(LaunchConfiguration("a"), value_type=str), "text": "off"}])
    visit(context, [node])
    assert context.processes[0].effective_parameters() == {"raw": False, "typed": "off", "text": "off"}


def test_rclpy_section_matching() -> None:
    assert rclpy_section_matches("execution_engine", "/execution_engine")
    assert not rclpy_section_matches("execution_engine", "/cell_a/execution_engine")
    assert rclpy_section_matches("/**/execution_engine", "/execution_engine")
    assert rclpy_section_matches("/**/execution_engine", "/plant/cell_a/execution_engine")
    assert not rclpy_section_matches("/**/execution_engine", "/cell_a/arm_machine")
    assert rclpy_section_matches("/*/arm_machine", "/cell_a/arm_machine") and not rclpy_section_matches("/*/arm_machine", "/arm_machine")


# ================================================================================ launch files
def console_scripts() -> set[str]:
    tree = ast.parse((ROOT / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == "console_scripts":
                    return {ast.literal_eval(item).split("=")[0].strip() for item in value.elts}  # type: ignore[attr-defined]
    raise AssertionError("setup.py declares no console_scripts")


def installed_folders() -> set[str]:
    """The folders setup.py installs whole under share/<package> (``*tree("launch")`` ...)."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    return {
        call.args[0].value
        for call in ast.walk(tree)
        if isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id == "tree" and isinstance(call.args[0], ast.Constant)
    }


def test_setup_installs_the_launch_and_config_folders_whole() -> None:
    assert {"launch", "config", "apps_xml"} <= installed_folders()
    assert {p.name for p in (ROOT / "launch").glob("*.launch.py")} == {cell.launch.name for cell in CELLS}


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_the_launch_file_starts_installed_executables_with_installed_files(cell: Cell, fake_launch: None) -> None:
    started = launch(cell)
    assert set(started) == cell.nodes
    assert {node.executable for node in started.values()} == {cell.bridge, "group_machine", ENGINE_NODE}
    assert {node.executable for node in started.values()} <= console_scripts()
    for node in started.values():
        assert node.package == "dual_arm_executive" and node.output == "screen"
        config_file, _ = node.parameters
        assert config_file == Path(f"{SHARE}/config/{cell.config.name}")
    for path in (cell.config, cell.launch, ROOT / "apps_xml" / cell.application, ROOT / "launch" / "cell_description.py"):
        assert path.is_file() and path.relative_to(ROOT).parts[0] in installed_folders()


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_the_launch_arguments_have_descriptions_and_their_parameters_defaults(cell: Cell, fake_launch: None) -> None:
    arguments = declared_arguments(cell)
    assert set(arguments) == {"application", *ROS_ARGUMENTS, *cell.arguments}
    assert all(a.given_description for a in arguments.values())
    assert arguments["application"].default_value == f"{SHARE}/apps_xml/{cell.application}"
    for name, default in ROS_ARGUMENTS.items():
        assert arguments[name].default_value == default
    bridge = config(cell)[cell.bridge]
    for name, (parameter, _) in cell.arguments.items():  # the argument's default is the parameter's
        assert arguments[name].default_value == str(bridge[parameter])


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_by_default_the_cell_starts_in_the_root_namespace_with_its_parameters(cell: Cell, fake_launch: None) -> None:
    started = launch(cell)
    sections, given = config(cell), cell.set_by_launch()
    for name, node in started.items():
        assert node.namespace == "/" and node.fqn == f"/{name}"
        assert node.effective_parameters() == {**sections[name], **given[name], "use_sim_time": False}
        assert node.ros_arguments()[:2] == ["--log-level", "info"]


@pytest.mark.parametrize("namespace", ["cell_a", "/cell_a", "plant/cell_a/"])
@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_namespace_use_sim_time_and_log_level_reach_every_node(cell: Cell, namespace: str, fake_launch: None) -> None:
    started = launch(cell, namespace=namespace, use_sim_time="true", log_level="debug")
    expected_ns = "/" + namespace.strip("/")
    sections, given = config(cell), cell.set_by_launch()
    for name, node in started.items():
        assert node.namespace == expected_ns and node.fqn == f"{expected_ns}/{name}"
        # the YAML still configures the node in its namespace, and use_sim_time is the bool true
        assert node.effective_parameters() == {**sections[name], **given[name], "use_sim_time": True}
        assert node.ros_arguments()[:2] == ["--log-level", "debug"]
        assert node.remapped("/clock") == f"{expected_ns}/clock"


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_two_cells_in_two_namespaces_share_no_node_and_no_clock(cell: Cell, fake_launch: None) -> None:
    cell_a, cell_b = launch(cell, namespace="cell_a"), launch(cell, namespace="cell_b")
    assert not {n.fqn for n in cell_a.values()} & {n.fqn for n in cell_b.values()}
    assert not {n.remapped("/clock") for n in cell_a.values()} & {n.remapped("/clock") for n in cell_b.values()}


def _probe(argument: DeclareLaunchArgument, value_type: type) -> str:
    """A value for the argument that YAML typing would get wrong (``off`` is a bool to rcl)."""
    if argument.choices:
        return argument.choices[-1]
    return {str: "off", int: "4321", float: "10"}[value_type]


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_launch_arguments_reach_their_parameters_typed_like_the_parameters(cell: Cell, fake_launch: None) -> None:
    arguments = declared_arguments(cell)
    targets = {name: (cell.bridge, parameter, value_type) for name, (parameter, value_type) in cell.arguments.items()}
    targets["application"] = (ENGINE_NODE, "application", str)
    sections = config(cell)
    for argument, (node, parameter, value_type) in targets.items():
        assert type(sections[node][parameter]) is value_type, f"{cell.name}: {node}.{parameter} in the YAML is not a {value_type.__name__}"
        probe = _probe(arguments[argument], value_type)
        value = launch(cell, **{argument: probe})[node].effective_parameters()[parameter]
        assert type(value) is value_type and value == value_type(probe), f"{argument}:={probe} gave {node}.{parameter} = {value!r}"


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_an_unknown_log_level_is_refused_before_any_node_starts(cell: Cell, fake_launch: None) -> None:
    with pytest.raises(RuntimeError, match="log_level"):
        launch(cell, log_level="verbose")


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_ros_node_names_are_the_embedded_deployments(cell: Cell, run_sim: Any) -> None:
    async def main(clock: Clock) -> list[str]:
        transport = LocalTransport(clock)
        deployment = await deploy_local(clock, cell.robot, ScriptedBackend(clock, cell.robot, {}), transport=transport)
        try:
            return transport.node_names()
        finally:
            await deployment.close()

    names = set(run_sim(main))
    assert {f"/{n}" for n in cell.nodes - {cell.bridge}} <= names


# ================================================================================ config files
async def _declared(clock: Clock, cell: Cell, name: str, overrides: dict[str, Any] | None = None) -> Node:
    """A node of ``name`` with every parameter its entry point declares."""
    node = LocalTransport(clock).create_node(name, parameters=overrides)
    if name == ENGINE_NODE:
        declare_engine_parameters(node)
        ExecutionEngine(node, APPLICATION_FUNCTIONS.catalog(None))
    elif name == cell.bridge:
        cell.declare(node)
        BridgeNode(node, ScriptedBackend(clock, cell.robot, {}))
    else:
        GroupMachine(node, APPLICATION_FUNCTIONS).close()
    return node


@pytest.mark.parametrize(("cell", "name"), NODES, ids=NODE_IDS)
def test_the_config_lists_every_declared_parameter_with_its_default(cell: Cell, name: str, run_sim: Any) -> None:
    section = config(cell)[name]
    machine = {key: section[key] for key in ("group", "robot") if key in section} or None
    declared = run_sim(lambda clock: _declared(clock, cell, name, machine)).declared_parameters()
    assert set(section) == set(declared)
    for key, value in section.items():
        assert type(value) is type(declared[key]), f"{name}.{key}: YAML {value!r} is not a {type(declared[key]).__name__}"
        assert value == declared[key], f"{name}.{key}: YAML says {value!r}, the code's default is {declared[key]!r}"


@pytest.mark.parametrize(("cell", "name"), NODES, ids=NODE_IDS)
def test_the_config_loads_as_overrides_without_a_stray_key(cell: Cell, name: str, run_sim: Any) -> None:
    node = run_sim(lambda clock: _declared(clock, cell, name, config(cell)[name]))
    assert node.undeclared_overrides() == []
    assert not set(config(cell)[name]) & RCLPY_OWN_PARAMETERS  # use_sim_time comes from the launch file


@pytest.mark.parametrize("cell", CELLS, ids=CELL_IDS)
def test_the_config_has_a_section_for_each_started_node_in_any_namespace(cell: Cell) -> None:
    keys = set(yaml.safe_load(cell.config.read_text()))
    assert keys == {f"/**/{name}" for name in cell.nodes}


# ====================================================================== a simulator's clock
@pytest.mark.parametrize(("speed", "use_sim_time", "follows"), [
    ("10.0", "false", True), ("0.5", "false", True), ("1.0", "false", False), ("1", "false", False), ("1.0", "true", True),
])
def test_a_simulator_off_real_time_is_the_clock_the_machines_and_the_engine_follow(
    speed: str, use_sim_time: str, follows: bool, fake_launch: None
) -> None:
    """speed:=10.0 makes the simulator publish /clock: every other node takes its time from it (their
    timeouts, the engine's report), whatever use_sim_time says; the bridge is the clock, it follows nothing."""
    cell = CELLS[0]
    assert cell.name == "nextage_sim"
    started = launch(cell, speed=speed, use_sim_time=use_sim_time)
    for name, node in started.items():
        expected = use_sim_time == "true" or (follows and name != cell.bridge)
        assert node.effective_parameters()["use_sim_time"] is expected, f"{name} at speed:={speed}"


def test_the_nodes_a_scaled_simulator_launches_run_on_its_clock_under_rclpy(fake_launch: None, fake_rclpy: Any) -> None:
    """What ros2 launch hands each node of nextage_sim.launch.py speed:=10.0, given to the rclpy
    transport (the fake rclpy): the engine and the machines measure time on /clock, the bridge does not."""
    cell = CELLS[0]
    started = launch(cell, speed="10.0")

    async def main(clock: Clock) -> dict[str, bool]:
        transport = RosTransport(clock, ["launched"])
        try:
            return {
                name: isinstance(transport.create_node(name, parameters={"use_sim_time": node.effective_parameters()["use_sim_time"]}).clock, FollowingClock)
                for name, node in started.items()
            }
        finally:
            await transport.shutdown()

    assert run_real(main) == {name: name != cell.bridge for name in cell.nodes}
