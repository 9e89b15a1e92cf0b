"""The ROS arguments of a node process on the DDS transport, read as rcl reads them.

Without rcl, the same command lines must still work: ``--ros-args -p name:=value``,
``--params-file FILE`` (sections ``/**/node``, ``/**``, ``node``), ``-r __node:=name``,
``-r __ns:=/ns``, topic and service remaps ``-r from:=to`` and ``--log-level``.  Values are typed
with YAML rules as rcl types them (``-p speed:=2`` is an integer, then the declared type decides);
:func:`node_transport.ros_args.raw_parameter_texts` keeps the text the user wrote for
string parameters.  Anything rcl would refuse is a :class:`RosArgumentsError` in one line.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from node_transport.parameters import ParameterValue
from node_transport.port import RosArgumentsError
from node_transport.ros_args import MAX_PARAMS_FILE, node_section_matches, ros_argument_tokens

_LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warn": logging.WARNING, "error": logging.ERROR, "fatal": logging.CRITICAL}


@dataclass
class RosArguments:
    """What the ROS arguments of one process say."""

    node_name: str | None = None
    namespace: str | None = None
    parameters: dict[str, ParameterValue] = field(default_factory=dict)
    param_files: list[tuple[str, dict[str, Any]]] = field(default_factory=list)  # in order, with -p interleaved
    remaps: dict[str, str] = field(default_factory=dict)
    log_level: int | None = None
    order: list[tuple[str, Any]] = field(default_factory=list)

    def overrides_for(self, node_fqn: str) -> dict[str, ParameterValue]:
        """The parameters meant for ``node_fqn``; later arguments win, as in rcl."""
        values: dict[str, ParameterValue] = {}
        for kind, item in self.order:
            if kind == "p":
                values[item[0]] = item[1]
            else:
                for section, body in item.items():
                    if isinstance(section, str) and isinstance(body, dict) and node_section_matches(section, node_fqn):
                        params = body.get("ros__parameters")
                        if isinstance(params, dict):
                            values.update(_flatten(params))
        return values


def _flatten(params: dict[str, Any], prefix: str = "") -> dict[str, ParameterValue]:
    out: dict[str, ParameterValue] = {}
    for key, value in params.items():
        if isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _yaml() -> Any:
    try:
        import yaml  # optional: PyYAML, only for a parameters file; without it such a file is refused in one line
    except ImportError:
        raise RosArgumentsError("parameters need PyYAML: pip install '.[dds]'") from None
    return yaml


def _typed(name: str, text: str) -> ParameterValue:
    yaml = _yaml()
    try:
        value = yaml.safe_load(text) if text.strip() else ""
    except yaml.YAMLError:
        value = text
    if value is None:
        return text
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list) and all(isinstance(v, (bool, int, float, str)) for v in value):
        return value
    raise RosArgumentsError(f"parameter {name!r}: cannot use value {text!r} (a scalar or a list of scalars)")


def _read_params_file(path: str) -> dict[str, Any]:
    yaml = _yaml()
    try:
        with Path(path).open("rb") as stream:
            data = stream.read(MAX_PARAMS_FILE + 1)
    except OSError as error:
        raise RosArgumentsError(f"cannot read params file {path}: {error.strerror}") from None
    if len(data) > MAX_PARAMS_FILE:
        raise RosArgumentsError(f"params file {path} is larger than {MAX_PARAMS_FILE} bytes")
    try:
        document = yaml.safe_load(data)
    except yaml.YAMLError as error:
        raise RosArgumentsError(f"cannot parse params file {path}: {' '.join(str(error).split())}") from None
    if not isinstance(document, dict):
        raise RosArgumentsError(f"params file {path}: expected sections like '/**/node: {{ros__parameters: ...}}'")
    return document


def parse_ros_arguments(argv: Sequence[str]) -> RosArguments:
    """Parse every ``--ros-args ... [--]`` section of ``argv``."""
    tokens = ros_argument_tokens(argv)
    args = RosArguments()
    index = 0
    while index < len(tokens):
        flag = tokens[index]
        value = tokens[index + 1] if index + 1 < len(tokens) else None
        if flag in ("-p", "--param", "-r", "--remap", "--params-file", "--log-level", "-e", "--enclave"):
            if value is None:
                raise RosArgumentsError(f"argument {flag} needs a value")
            index += 2
        else:
            raise RosArgumentsError(f"unknown ROS argument {flag!r}")
        if flag in ("-p", "--param"):
            name, sep, text = value.partition(":=")
            if not sep or not name:
                raise RosArgumentsError(f"couldn't parse parameter override rule: '{flag} {value}'. Expected '<name>:=<value>'")
            args.order.append(("p", (name, _typed(name, text))))
        elif flag in ("-r", "--remap"):
            source, sep, target = value.partition(":=")
            if not sep or not source or not target:
                raise RosArgumentsError(f"couldn't parse remap rule: '{flag} {value}'. Expected '<match>:=<replacement>'")
            if source == "__node" or source == "__name":
                args.node_name = target
            elif source == "__ns":
                args.namespace = target if target.startswith("/") else "/" + target
            else:
                args.remaps[source] = target
        elif flag == "--params-file":
            args.order.append(("f", _read_params_file(value)))
        elif flag == "--log-level":
            level = _LEVELS.get(value.lower().rpartition(":=")[2] if ":=" in value else value.lower())
            if level is None:
                raise RosArgumentsError(f"--log-level {value}: use one of {', '.join(_LEVELS)}")
            args.log_level = level
    return args


def user_arguments(argv: Sequence[str]) -> list[str]:
    """``argv`` without the program name and without ROS arguments (``--ros-args ... --``)."""
    out: list[str] = []
    inside = False
    for arg in list(argv)[1:]:
        if arg == "--ros-args":
            inside = True
        elif arg == "--" and inside:
            inside = False
        elif not inside:
            out.append(arg)
    return out
