"""The back end an engine node checks runs on: its parameters ``check_backend`` and ``check_options``.

``launch`` starts the bridge of the robot (``--robot``, ``--backend-option``) and the engine in separate processes.
The engine's start check dry-runs each run, and that dry run must be the one ``run --robot B --backend-option ...``
does: the model of the back end the bridge really drives, with the same options (a ros2-control robot's URDF,
controllers and grippers, an RSI configuration), not the robot model's usual simulator.  So the launcher hands the
engine the bridge's back end and options as two string parameters; a hand-started engine without them checks on
the robot model's default back end, as before.  ``check_options`` is ``KEY=VALUE;KEY=VALUE`` (the form of the
machines' ``cell_names``), in the order given (a later key wins, as in ``--backend-option``).
"""
from __future__ import annotations

import json
from collections.abc import Sequence

SEPARATOR = ";"


def options_text(options: Sequence[tuple[str, str]]) -> str:
    """``check_options`` of ``options``; ValueError naming an option the text cannot carry."""
    for key, value in options:
        if SEPARATOR in key or SEPARATOR in value or "=" in key:
            raise ValueError(
                f"--backend-option {key}={value}: the engine's check cannot be given a '{SEPARATOR}' (its parameter check_options is "
                "KEY=VALUE;KEY=VALUE): name it without one, or launch with --no-check"
            )
    return SEPARATOR.join(f"{key}={value}" for key, value in options)


def options_parameter(options: Sequence[tuple[str, str]]) -> str:
    """``-p check_options:=...`` with the text quoted: ROS reads a ``-p`` value as YAML, and a value with ``#`` or ``: ``
    in it (a file name, a tool offset) must reach the engine as the same string."""
    return f"check_options:={json.dumps(options_text(options))}"


def options_from_text(text: str) -> dict[str, str]:
    """The options of a ``check_options`` parameter; ValueError naming the item that is not KEY=VALUE."""
    options: dict[str, str] = {}
    for item in text.split(SEPARATOR):
        if not item.strip():
            continue
        key, equals, value = item.partition("=")
        if not equals or not key.strip():
            raise ValueError(f"parameter check_options: {item.strip()!r} is not KEY=VALUE (the items are separated by '{SEPARATOR}')")
        options[key.strip()] = value.strip()
    return options
