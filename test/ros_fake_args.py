"""rcl's handling of ``--ros-args``, as the fake rclpy needs it (rcl 9.2 / rclpy 7.1, ROS 2 Jazzy).

Modelled from rcl's ``arguments.c`` and ``rcl_yaml_param_parser/parse.c`` and rclpy's
``node.cpp``, because these are exactly the behaviours a user meets and the fake must not be
kinder than the real thing:

* ``rclpy.init`` refuses what rcl cannot parse: ``-p name`` without ``:=`` (``RCLError``, "failed
  to initialize rcl: Couldn't parse parameter override rule ..."), a flag without its value, a
  params file that does not exist or is not valid YAML; an unknown flag after ``--ros-args``
  raises ``UnknownROSArgsError`` listing it.
* Parameter values are typed by rcl's ``get_value``: unquoted ``Y y yes Yes YES true True TRUE
  on On ON`` are true and their ``n/no/false/off`` forms false; then an integer by
  ``strtoll(value, 0)`` (``0x10`` is 16, ``010`` is 8); then a double by ``strtod`` (``1e3``,
  ``.inf``); a quoted scalar is always a string.  ``[a, b]`` is an array of one type.
* A params file section applies to a node when its name matches the node's fully qualified
  name with ``/*`` as one token and ``/**`` as any number of them; ``-p`` applies to all nodes;
  later rules override earlier ones.
* ``--log-level LEVEL`` (or ``name:=LEVEL``) sets the default logger level.
"""
from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

from node_transport.ros_args import ros_argument_tokens


class RCLError(RuntimeError):
    """rclpy._rclpy_pybind11.RCLError."""


class UnknownROSArgsError(RuntimeError):
    """rclpy._rclpy_pybind11.UnknownROSArgsError."""


class InvalidHandle(Exception):
    """rclpy._rclpy_pybind11.InvalidHandle: an entity used after it was destroyed."""


_TRUE = {"Y", "y", "yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"}
_FALSE = {"N", "n", "no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"}
_SPECIAL_FLOATS = {".nan", ".NaN", ".NAN", ".inf", ".Inf", ".INF", "+.inf", "+.Inf", "+.INF", "-.inf", "-.Inf", "-.INF"}
_FLAGS_WITH_VALUE = {"-p", "--param", "-r", "--remap", "-e", "--enclave", "--params-file", "--log-level",
                     "--log-config-file", "--log-file-name"}
_FLAGS_ALONE = {"--enable-rosout-logs", "--disable-rosout-logs", "--enable-stdout-logs", "--disable-stdout-logs",
                "--enable-external-lib-logs", "--disable-external-lib-logs"}
_LEVELS = {"debug": 10, "info": 20, "warn": 30, "error": 40, "fatal": 50}
_STRTOLL = re.compile(r"\s*([+-]?)(0[xX]([0-9a-fA-F]+)|0([0-7]*)|([1-9][0-9]*))")
_STRTOD = re.compile(
    r"\s*[+-]?(0[xX]([0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)([pP][+-]?\d+)?"
    r"|(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|inf(inity)?|nan)",
    re.I,
)


def _strtoll0(text: str) -> int | None:
    """C's strtoll(text, &end, 0), when it consumes the whole text."""
    match = _STRTOLL.match(text)
    if match is None or match.end() != len(text):
        return None
    sign, _, hexa, octal, decimal = match.groups()
    value = int(hexa, 16) if hexa is not None else int(octal, 8) if octal else int(decimal) if decimal else 0
    return -value if sign == "-" else value


def scalar(text: str, quoted: bool = False) -> Any:
    """rcl's get_value for one scalar."""
    if quoted:
        return text
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    integer = _strtoll0(text) if text else None
    if integer is not None:
        return integer
    if text in _SPECIAL_FLOATS:
        value = math.nan if "nan" in text.lower() else math.inf
        return -value if text.startswith("-") else value
    match = _STRTOD.match(text) if text else None
    if match is not None and match.end() == len(text):
        body = text.strip()
        return float.fromhex(body) if "x" in body.lower() else float(body)
    return text


def _typed(node: yaml.Node, where: str) -> Any:
    """A YAML node typed the rcl way (arrays of one type; mappings nest parameter names)."""
    if isinstance(node, yaml.ScalarNode):
        return scalar(node.value, quoted=node.style in ("'", '"'))
    if isinstance(node, yaml.SequenceNode):
        items = [_typed(item, where) for item in node.value]
        kinds = {type(v) for v in items}
        if len(kinds) > 1:
            raise RCLError(f"failed to initialize rcl: Sequence should be of same type. Value type 'mixed' do not belong at line_num {node.start_mark.line + 1}, at ./src/parse.c:1")
        return items
    if isinstance(node, yaml.MappingNode):
        return {key.value: _typed(value, where) for key, value in node.value}
    raise RCLError(f"failed to initialize rcl: {where}: unsupported YAML")


def parse_value(text: str) -> Any:
    """``-p name:=text``: the text is a YAML document."""
    try:
        node = yaml.compose(text)
    except yaml.YAMLError as error:
        raise RCLError(f"failed to initialize rcl: Couldn't parse parameter override rule: '{text}': {error}, at ./src/rcl/arguments.c:1") from None
    if node is None:
        return ""
    return _typed(node, text)


def _flatten(values: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    for key, value in values.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def params_file(path: str) -> list[tuple[str, dict[str, Any]]]:
    """(node section, parameters) of a params file, typed as rcl types them."""
    flag = f"--params-file {path}"
    try:
        text = Path(path).read_text()
    except OSError as error:
        raise RCLError(f"failed to initialize rcl: Couldn't parse params file: '{flag}'. Error: Error opening YAML file, {error}, at ./src/rcl/arguments.c:415") from None
    try:
        root = yaml.compose(text)
    except yaml.YAMLError as error:
        raise RCLError(f"failed to initialize rcl: Couldn't parse params file: '{flag}'. Error: Error parsing a event near line {getattr(error, 'problem_mark', None)}, at ./src/rcl/arguments.c:415") from None
    sections: list[tuple[str, dict[str, Any]]] = []
    if root is None:
        return sections
    if not isinstance(root, yaml.MappingNode):
        raise RCLError(f"failed to initialize rcl: Couldn't parse params file: '{flag}'. Error: the first level must be node names, at ./src/rcl/arguments.c:415")
    for key, body in root.value:
        typed = _typed(body, path)
        params = typed.get("ros__parameters") if isinstance(typed, dict) else None
        if not isinstance(params, dict):
            raise RCLError(f"failed to initialize rcl: Couldn't parse params file: '{flag}'. Error: There are no node names before ros__parameters, at ./src/rcl/arguments.c:415")
        sections.append((key.value, dict(_flatten(params))))
    return sections


class RosArguments:
    """The ROS part of one argv, parsed and checked as rcl does in ``rcl_init``."""

    def __init__(self, argv: list[str]) -> None:
        self.rules: list[tuple[str, dict[str, Any]]] = []  # (node section, params), in order
        self.remaps: dict[str, str] = {}
        self.log_level: int | None = None
        unknown: list[str] = []
        tokens = ros_argument_tokens(argv)  # splitting the sections is not where rcl's rules live
        index = 0
        while index < len(tokens):
            flag = tokens[index]
            if flag in _FLAGS_ALONE:
                index += 1
                continue
            if flag not in _FLAGS_WITH_VALUE:
                unknown.append(flag)
                index += 1
                continue
            if index + 1 >= len(tokens):
                raise RCLError(f"failed to initialize rcl: Couldn't parse trailing {flag} flag. No {'file path' if flag == '--params-file' else 'rule'} provided., at ./src/rcl/arguments.c:420")
            value = tokens[index + 1]
            index += 2
            if flag in ("-p", "--param"):
                name, sep, text = value.partition(":=")
                if not sep or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.]*", name):
                    raise RCLError(f"failed to initialize rcl: Couldn't parse parameter override rule: '{flag} {value}'. Error: Expected lexeme type (22) not found, search ended at index {len(value)}, at ./src/rcl/arguments.c:359")
                self.rules.append(("/**", {name: parse_value(text)}))
            elif flag in ("-r", "--remap"):
                source, sep, target = value.partition(":=")
                if not sep:
                    raise RCLError(f"failed to initialize rcl: Couldn't parse remap rule: '{flag} {value}'. Error: Expected lexeme type (19) not found, search ended at index 1, at ./src/rcl/arguments.c:387")
                self.remaps[source] = target
            elif flag == "--params-file":
                self.rules.extend(params_file(value))
            elif flag == "--log-level":
                level = value.partition(":=")[2] or value
                if level.lower() not in _LEVELS:
                    raise RCLError(f"failed to initialize rcl: Couldn't parse log level rule: '{flag} {value}'. Error: Argument does not have a valid severity level: '{level}', at ./src/rcl/arguments.c:448")
                if ":=" not in value:
                    self.log_level = _LEVELS[level.lower()]
        if unknown:
            raise UnknownROSArgsError(repr(unknown))

    def parameters_for(self, node_fqn: str) -> dict[str, Any]:
        """rclpy's ``Node.get_parameters``: the overrides of every matching section, later ones winning."""
        found: dict[str, Any] = {}
        for section, params in self.rules:
            name = section if section.startswith("/") else "/" + section
            pattern = re.escape(name).replace(r"/\*\*", r"(/\w+)*").replace(r"/\*", r"(/\w+)")
            if re.fullmatch(pattern, node_fqn):
                found.update(params)
        return found
