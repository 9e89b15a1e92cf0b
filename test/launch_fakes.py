"""A model of ``launch`` 3.4 / ``launch_ros`` 0.26 (ROS 2 Jazzy) for running the project's launch files without ROS 2.

``test_ros_launch.py`` runs each launch file the way ``ros2 launch`` runs it against this model and checks what each
node would get.  The model keeps the signatures and the rules these files rely on -- launch arguments with their
defaults and choices, node namespaces (``Node(namespace=...)``, ``PushRosNamespace`` in a ``GroupAction``),
parameter files and dictionaries evaluated with launch_ros' typing, remappings and ROS arguments -- and resolves a
node's parameters as rclpy does (params-file sections matched against the node's fully qualified name).  Anything
else a launch file calls is missing here and fails loudly.  The ``fake_launch`` fixture puts it in ``sys.modules``.
"""
from __future__ import annotations

import math
import re
import sys
import types
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
#: The package's share directory once installed; its files are read from the source tree.
SHARE = "/opt/ws/install/dual_arm_executive/share/dual_arm_executive"


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


def _bool_like(text: str) -> bool:
    return text.lower() in ("true", "false", "1", "0")


def _float_like(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


class NotEqualsSubstitution(Substitution):
    """launch.substitutions.NotEqualsSubstitution: 'true' unless both sides are equal -- as booleans when
    both read as one (true/false/1/0), as numbers (math.isclose) when both read as one, else as text."""

    def __init__(self, left: Any, right: Any) -> None:
        self.left, self.right = left, right

    def perform(self, context: LaunchContext) -> str:
        left, right = (v if isinstance(v, (str, Substitution, list)) else str(v) for v in (self.left, self.right))
        left, right = perform(context, left), perform(context, right)
        if _bool_like(left) and _bool_like(right):
            equal = (left.lower() in ("true", "1")) == (right.lower() in ("true", "1"))
        elif _float_like(left) and _float_like(right):
            equal = math.isclose(float(left), float(right))
        else:
            equal = left == right
        return str(not equal).lower()


class OrSubstitution(Substitution):
    """launch.substitutions.OrSubstitution: each side typed as a bool (launch's YAML rules), 'true' or 'false'."""

    def __init__(self, left: Any, right: Any) -> None:
        self.left, self.right = left, right

    def perform(self, context: LaunchContext) -> str:
        try:
            left, right = (coerce_to_type(perform(context, side), bool) for side in (self.left, self.right))
        except (TypeError, ValueError) as error:
            raise SubstitutionFailure(error) from None
        return str(left or right).lower()


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


def launch_modules() -> dict[str, types.ModuleType]:
    """The modules of launch, launch_ros and ament_index_python a launch file imports, made of this model."""
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
        "launch.substitutions": module(
            "launch.substitutions", LaunchConfiguration=LaunchConfiguration, SubstitutionFailure=SubstitutionFailure,
            NotEqualsSubstitution=NotEqualsSubstitution, OrSubstitution=OrSubstitution,
        ),
        "launch_ros": module("launch_ros"),
        "launch_ros.actions": module("launch_ros.actions", Node=LaunchNode, **push),
        "launch_ros.parameter_descriptions": module("launch_ros.parameter_descriptions", ParameterValue=ParameterValue),
        "ament_index_python": module("ament_index_python"),
        "ament_index_python.packages": module("ament_index_python.packages", get_package_share_directory=share_directory),
    }


@pytest.fixture
def fake_launch(monkeypatch: pytest.MonkeyPatch) -> None:
    """This model installed as launch and launch_ros for one test (import this fixture into a test module)."""
    for name, module in launch_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
