"""The launch files and their parameter files agree with the code they start.

Each launch file (Nextage simulator, V+, KUKA RSI) is run the way ``ros2 launch`` runs it, against
a small model of ``launch`` / ``launch_ros`` (jazzy: launch 3.4, launch_ros 0.26) that keeps their
signatures and the rules these files rely on: launch arguments and their defaults and choices,
node namespaces (``Node(namespace=...)``, ``PushRosNamespace`` in a ``GroupAction``), parameter
files and dictionaries evaluated with launch_ros' typing, remappings and ROS arguments.  What a
node then gets is resolved as rclpy resolves it (params-file sections matched against the node's
fully qualified name), so the tests see each node's namespace, parameters and command line.  The
YAML files are compared with the parameters the nodes really declare, by building those nodes on
the local transport.
"""
from __future__ import annotations

import ast
import re
import sys
import types
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib.machinery import SourceFileLoader
from importlib.util import module_from_spec, spec_from_loader
from pathlib import Path
from typing import Any

import pytest
import yaml
from scripted_backend import ScriptedBackend

from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN, RobotModel
from execution_engine.clock import Clock
from execution_engine.deployment import deploy_local
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.machine.group_machine import GroupMachine
from execution_engine.nodes import declare_engine_parameters
from execution_engine.ros_main import ENGINE_NODE, bridge_node_name, machine_node_name
from execution_engine.transport.local import LocalTransport
from execution_engine.transport.port import Node
from execution_engine.transport.ros_convert import RCLPY_OWN_PARAMETERS
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.kuka_rsi.node import BACKEND as KUKA_RSI, declare_kuka_parameters
from robot_bridges.nextage_sim.node import BACKEND as NEXTAGE_SIM, declare_nextage_parameters
from robot_bridges.node import BridgeSetup
from robot_bridges.vplus.node import BACKEND as VPLUS, declare_vplus_parameters

ROOT = Path(__file__).resolve().parent.parent
SHARE = "/opt/ws/install/dual_arm_executive/share/dual_arm_executive"


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


# ======================================================================= launch and launch_ros
# The parts of launch 3.4 / launch_ros 0.26 (ROS 2 jazzy) these launch files use, with their
# signatures; anything else a launch file calls is missing here and fails loudly.
class SubstitutionFailure(Exception):
    pass


class LaunchContext:
    def __init__(self, arguments: dict[str, str]) -> None:
        self.launch_configurations: dict[str, Any] = dict(arguments)  # ros2 launch sets them first
        self.processes: list[StartedNode] = []


class Substitution:
    def perform(self, context: LaunchContext) -> str:
        raise NotImplementedError


class LaunchConfiguration(Substitution):
    def __init__(self, variable_name: Any, *, default: Any = None) -> None:
        self.variable_name, self.default = variable_name, default

    def perform(self, context: LaunchContext) -> str:
        name = perform(context, self.variable_name)
        if name in context.launch_configurations:
            return str(context.launch_configurations[name])
        if self.default is None:
            raise SubstitutionFailure(f"launch configuration '{name}' does not exist")
        return perform(context, self.default)


def perform(context: LaunchContext, value: Any) -> str:
    """launch.utilities.perform_substitutions of a SomeSubstitutionsType."""
    if isinstance(value, str):
        return value
    if isinstance(value, Substitution):
        return value.perform(context)
    return "".join(perform(context, item) for item in value)


def coerce_to_type(value: str, data_type: type | None) -> Any:
    """launch.utilities.type_utils.coerce_to_type for scalars."""
    if data_type is str:
        return value
    if data_type in (int, float):
        return data_type(value)
    if data_type is bool:
        value = {"1": "true", "0": "false"}.get(value, value)
    output = yaml.safe_load(value) if value else value
    if data_type is not None and not isinstance(output, data_type):
        raise ValueError(f"Cannot convert value '{value}' to '{data_type}'")
    return output


class ParameterValue:
    def __init__(self, value: Any, *, value_type: type | None = None) -> None:
        self.value, self.value_type = value, value_type

    def evaluate(self, context: LaunchContext) -> Any:
        if isinstance(self.value, (str, int, float, bool)):
            if self.value_type is not None and not isinstance(self.value, self.value_type):
                raise TypeError(f"value=`{self.value}` is a scalar and not an instance of `{self.value_type}`")
            return self.value
        return coerce_to_type(perform(context, self.value), self.value_type)


class Action:
    def __init__(self, *, condition: None = None) -> None:
        assert condition is None, "conditions are not modelled"

    def execute(self, context: LaunchContext) -> Iterable[Action]:
        raise NotImplementedError


class LaunchDescription:
    def __init__(self, initial_entities: Iterable[Action] | None = None, *, deprecated_reason: str | None = None) -> None:
        self.entities = list(initial_entities or [])


class DeclareLaunchArgument(Action):
    def __init__(
        self, name: str, *, default_value: Any = None, description: str | None = None, choices: list[str] | None = None, **kwargs: Any
    ) -> None:
        super().__init__(**kwargs)
        if choices is not None and (not choices or (isinstance(default_value, str) and default_value not in choices)):
            raise RuntimeError(f"{name}: default_value {default_value!r} is not in choices {choices}")
        self.name, self.default_value, self.choices, self.given_description = name, default_value, choices, description
        if description is None:
            self.description = "no description given" if choices is None else f"One of: {choices}"
        else:
            self.description = description + ("" if choices is None else f"{'' if description.endswith('.') else '.'} Valid choices are: {choices}")

    def execute(self, context: LaunchContext) -> Iterable[Action]:
        if self.name not in context.launch_configurations:
            if self.default_value is None:
                raise RuntimeError(f'Required launch argument "{self.name}" was not provided.')
            context.launch_configurations[self.name] = perform(context, self.default_value)
        if self.choices is not None and context.launch_configurations[self.name] not in self.choices:
            raise RuntimeError(f'Argument "{self.name}" provided value "{context.launch_configurations[self.name]}" is not valid')
        return []


class GroupAction(Action):
    def __init__(
        self, actions: Iterable[Action], *, scoped: bool = True, forwarding: bool = True, launch_configurations: dict[Any, Any] | None = None, **kwargs: Any
    ) -> None:
        super().__init__(**kwargs)
        self.actions, self.scoped, self.forwarding = list(actions), scoped, forwarding
        self.launch_configurations = launch_configurations or {}

    def execute(self, context: LaunchContext) -> Iterable[Action]:
        saved = dict(context.launch_configurations)
        if self.scoped and not self.forwarding:
            context.launch_configurations.clear()
        for key, value in self.launch_configurations.items():
            context.launch_configurations[perform(context, key)] = perform(context, value)
        visit(context, self.actions)
        if self.scoped:
            context.launch_configurations = saved
        return []


def prefix_namespace(base_ns: str | None, ns: str | None) -> str | None:
    """launch_ros.utilities.prefix_namespace."""
    if base_ns is None and ns is None:
        return None
    if ns is None:
        combined = base_ns
    elif not base_ns or ns.startswith("/"):
        combined = ns
    else:
        combined = ("" if base_ns == "/" else base_ns) + "/" + ns
    assert combined is not None
    return combined if combined == "/" else combined.rstrip("/")


def make_namespace_absolute(ns: str | None) -> str | None:
    if ns is None:
        return None
    return ns if ns.startswith("/") else "/" + ns


def validate_namespace(ns: str) -> None:
    """rclpy.validate_namespace: absolute, tokens of letters, digits and _, no token starting with a digit."""
    if not re.fullmatch(r"/|(/[A-Za-z_][A-Za-z0-9_]*)+", ns):
        raise ValueError(f"invalid namespace {ns!r}")


class PushRosNamespace(Action):
    def __init__(self, namespace: Any, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.namespace = namespace

    def execute(self, context: LaunchContext) -> Iterable[Action]:
        previous = context.launch_configurations.get("ros_namespace")
        namespace = make_namespace_absolute(prefix_namespace(previous, perform(context, self.namespace)))
        assert namespace is not None
        validate_namespace(namespace)
        context.launch_configurations["ros_namespace"] = namespace
        return []


@dataclass
class StartedNode:
    """What a launch_ros Node action hands to the process it starts."""

    package: str
    executable: str
    name: str
    namespace: str
    parameters: list[Path | dict[str, Any]]  # params files, then dictionaries (launch_ros writes them to files keyed by the node)
    remappings: list[tuple[str, str]]
    command: list[str]
    output: str

    @property
    def fqn(self) -> str:
        return prefix_namespace(self.namespace, self.name) or ""

    def ros_arguments(self) -> list[str]:
        """Every token of every ``--ros-args`` section of the command line."""
        tokens, inside = [], False
        for token in self.command:
            if token == "--ros-args":
                inside = True
            elif inside:
                tokens.append(token)
        return tokens

    def effective_parameters(self) -> dict[str, Any]:
        """The overrides the node starts with, as rclpy resolves them: files in order, later wins."""
        resolved: dict[str, Any] = {}
        for entry in self.parameters:
            if isinstance(entry, dict):  # launch_ros dumps it with PyYAML under the node's name; rcl reads it back
                entry_file = yaml.safe_load(yaml.dump({self.fqn: {"ros__parameters": entry}}))
                resolved.update(entry_file[self.fqn]["ros__parameters"])
                continue
            assert str(entry).startswith(SHARE + "/"), f"{entry} is not in the package's share directory"
            for key, section in yaml.safe_load((ROOT / str(entry)[len(SHARE) + 1 :]).read_text()).items():
                if rclpy_section_matches(key, self.fqn):
                    resolved.update(section["ros__parameters"])
        return resolved

    def remapped(self, name: str) -> str:
        """Where a topic given as the absolute ``name`` ends up after the node's remap rules (rcl)."""
        for source, target in self.remappings:
            if source == name:
                return target if target.startswith("/") else prefix_namespace(self.namespace, target) or ""
        return name


def rclpy_section_matches(key: str, node_fqn: str) -> bool:
    """rclpy's rule for a params-file section (node.cpp): '/' prepended, '/*' is one token, '/**' any."""
    key = key if key.startswith("/") else "/" + key
    return re.fullmatch(key.replace("/*", r"(/\w+)"), node_fqn) is not None


EXECUTE_PROCESS_KEYWORDS = {
    "prefix", "cwd", "env", "additional_env", "shell", "sigterm_timeout", "sigkill_timeout", "emulate_tty", "output",
    "output_format", "cached_output", "log_cmd", "on_exit", "respawn", "respawn_delay", "respawn_max_retries", "condition",
}


class LaunchNode(Action):
    """launch_ros.actions.Node."""

    def __init__(
        self,
        *,
        executable: Any,
        package: Any = None,
        name: Any = None,
        namespace: Any = None,
        exec_name: Any = None,
        parameters: list[Any] | None = None,
        remappings: Iterable[tuple[Any, Any]] | None = None,
        ros_arguments: Iterable[Any] | None = None,
        arguments: Iterable[Any] | None = None,
        **kwargs: Any,
    ) -> None:
        unknown = set(kwargs) - EXECUTE_PROCESS_KEYWORDS
        if unknown:
            raise TypeError(f"Node() got unexpected keyword arguments {sorted(unknown)}")
        super().__init__(condition=kwargs.get("condition"))
        if parameters is not None and not isinstance(parameters, list):
            raise TypeError("'parameters' of Node must be a list")
        self.executable, self.package, self.name, self.namespace = executable, package, name, namespace
        self.parameters, self.remappings = parameters or [], list(remappings or [])
        self.ros_arguments, self.arguments, self.output = list(ros_arguments or []), list(arguments or []), kwargs.get("output", "log")

    def _parameter(self, context: LaunchContext, value: Any) -> Any:
        """launch_ros' normalize_parameter_dict + evaluate_parameter_dict for one scalar value."""
        if isinstance(value, ParameterValue):
            return value.evaluate(context)
        if isinstance(value, str):  # normalized as yaml.dump(value): the string survives
            return yaml.safe_load(yaml.dump(value))
        if isinstance(value, Substitution):  # evaluated with YAML rules: "off" becomes False
            return yaml.safe_load(perform(context, value) or "''")
        assert isinstance(value, (bool, int, float)), f"unexpected parameter value {value!r}"
        return value

    def execute(self, context: LaunchContext) -> Iterable[Action]:
        assert self.name is not None, "a node without name= gets its executable's default name: name every node"
        name = perform(context, self.name)
        assert re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name), f"invalid node name {name!r}"
        own = None if self.namespace is None else perform(context, self.namespace)
        namespace = make_namespace_absolute(prefix_namespace(context.launch_configurations.get("ros_namespace"), own))
        command = [perform(context, self.executable), *(perform(context, a) for a in self.arguments)]
        if self.ros_arguments:
            command += ["--ros-args", *(perform(context, a) for a in self.ros_arguments)]
        command += ["--ros-args", "-r", f"__node:={name}"]
        if namespace is not None:
            validate_namespace(namespace)
            command += ["-r", f"__ns:={namespace}"]
        parameters: list[Path | dict[str, Any]] = []
        for entry in self.parameters:
            if isinstance(entry, dict):
                parameters.append({perform(context, key): self._parameter(context, value) for key, value in entry.items()})
            else:
                parameters.append(Path(perform(context, entry)))
            command += ["--params-file", "<launch_params_file>" if isinstance(entry, dict) else str(entry)]
        remappings = [(perform(context, source), perform(context, target)) for source, target in self.remappings]
        for source, target in remappings:
            command += ["-r", f"{source}:={target}"]
        context.processes.append(
            StartedNode(perform(context, self.package or ""), perform(context, self.executable), name, namespace or "/", parameters, remappings, command, self.output)
        )
        return []


def visit(context: LaunchContext, entities: Iterable[Action]) -> None:
    for entity in entities:
        visit(context, entity.execute(context))


def _launch_modules() -> dict[str, types.ModuleType]:
    def module(name: str, **attributes: Any) -> types.ModuleType:
        made = types.ModuleType(name)
        made.__dict__.update(attributes)
        return made

    def share_directory(package: str) -> str:
        assert package == "dual_arm_executive"
        return SHARE

    push = {"PushRosNamespace": PushRosNamespace, "PushROSNamespace": PushRosNamespace}
    return {
        "launch": module("launch", LaunchDescription=LaunchDescription, LaunchContext=LaunchContext, Action=Action, Substitution=Substitution),
        "launch.actions": module("launch.actions", DeclareLaunchArgument=DeclareLaunchArgument, GroupAction=GroupAction),
        "launch.substitutions": module("launch.substitutions", LaunchConfiguration=LaunchConfiguration, SubstitutionFailure=SubstitutionFailure),
        "launch_ros": module("launch_ros"),
        "launch_ros.actions": module("launch_ros.actions", Node=LaunchNode, **push),
        "launch_ros.parameter_descriptions": module("launch_ros.parameter_descriptions", ParameterValue=ParameterValue),
        "ament_index_python": module("ament_index_python"),
        "ament_index_python.packages": module("ament_index_python.packages", get_package_share_directory=share_directory),
    }


@pytest.fixture
def fake_launch(monkeypatch: pytest.MonkeyPatch) -> None:
    for name, module in _launch_modules().items():
        monkeypatch.setitem(sys.modules, name, module)


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
        ExecutionEngine(node)
    elif name == cell.bridge:
        cell.declare(node)
        BridgeNode(node, ScriptedBackend(clock, cell.robot, {}))
    else:
        GroupMachine(node).close()
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
