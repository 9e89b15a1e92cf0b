"""What the user literally wrote for each parameter on the command line or in a params file.

rcl types every unquoted parameter value as YAML 1.1 would: ``-p initial_pose:=off`` arrives as
the bool ``False`` (so do ``yes``/``no``/``on``/``y``/``n``/``true``/``false`` in their case
variants), ``-p group:=0x10`` as the integer 16 and ``-p tag:=010`` as 8.  A string parameter
must still get the text the user meant, so the rclpy adapter reads the ROS arguments again here
and keeps every override as written; :meth:`node_transport.port.Node.declare_parameter`
uses that text when a string parameter received a value rcl typed otherwise.

Only the parts of rcl's rules that decide *which* text applies to a node are modelled: ``-p`` /
``--param name:=value`` applies to every node; ``--params-file FILE`` sections apply to the node
whose fully qualified name matches the section name (``/**`` any, ``/*`` one token; a name
without a leading ``/`` is absolute); later arguments override earlier ones.  Malformed input
is rcl's to refuse (it does, before a node exists); here it is skipped silently.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["raw_parameter_texts", "ros_argument_tokens"]

MAX_PARAMS_FILE = 1 << 20  # bytes read of one params file; rcl has read it whole already
_FLAGS_WITH_VALUE = {
    "-p", "--param", "-r", "--remap", "-e", "--enclave", "--params-file", "--log-level",
    "--log-config-file", "--log-file-name",
}


def ros_argument_tokens(argv: Sequence[str]) -> list[str]:
    """The tokens inside every ``--ros-args ... [--]`` section of ``argv``, in order."""
    tokens: list[str] = []
    inside = False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
        elif arg == "--" and inside:
            inside = False
        elif inside:
            tokens.append(arg)
    return tokens


def _rules(argv: Sequence[str]) -> Iterator[tuple[str, str]]:
    """(flag, value) pairs of the ROS arguments, for the flags that take a value."""
    tokens = ros_argument_tokens(argv)
    index = 0
    while index < len(tokens):
        flag = tokens[index]
        if flag in _FLAGS_WITH_VALUE and index + 1 < len(tokens):
            yield flag, tokens[index + 1]
            index += 2
        else:
            index += 1


def node_section_matches(section: str, node_fqn: str) -> bool:
    """rclpy's rule: ``/*`` stands for one name token, ``/**`` for any number of them."""
    name = section if section.startswith("/") else "/" + section
    pattern = re.escape(name).replace(r"/\*\*", "(/\\w+)*").replace(r"/\*", "(/\\w+)")
    return re.fullmatch(pattern, node_fqn) is not None


def _flatten(values: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, str]]:
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            yield from _flatten(value, name + ".")
        elif isinstance(value, str):
            yield name, value


def _read_params_file(path: str) -> Mapping[str, Any]:
    """The file as untyped YAML (every scalar a string), or {} when it cannot be read."""
    try:
        import yaml  # optional: a dependency of every ROS 2 install; the parser only matters there
    except ImportError:
        return {}
    try:
        with Path(path).open("rb") as stream:
            text = stream.read(MAX_PARAMS_FILE)
        document = yaml.load(text, Loader=yaml.BaseLoader)  # noqa: S506 - BaseLoader builds no objects
    except (OSError, yaml.YAMLError):
        return {}
    return document if isinstance(document, Mapping) else {}


def raw_parameter_texts(
    argv: Sequence[str], node_fqn: str, read_file: Callable[[str], Mapping[str, Any]] = _read_params_file
) -> dict[str, str]:
    """Parameter name -> the text given for it to node ``node_fqn`` (scalars only; last one wins)."""
    texts: dict[str, str] = {}
    for flag, value in _rules(argv):
        if flag in ("-p", "--param"):
            name, sep, text = value.partition(":=")
            if sep and name:
                texts[name] = text.strip()
        elif flag == "--params-file":
            for section, body in read_file(value).items():
                if not (isinstance(section, str) and isinstance(body, Mapping) and node_section_matches(section, node_fqn)):
                    continue
                params = body.get("ros__parameters")
                if isinstance(params, Mapping):
                    texts.update(_flatten(params))
    return texts
