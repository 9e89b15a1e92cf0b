"""A Nextage application whose restart from the middle drives the hands into each other, and a
collision watch on ``joint_states`` (issue 20, finding 4).

``CROSSING``: the right hand goes to the middle of the table and back home, then the left hand
goes to the middle and stays there while the left arm waits 30 s.  A run cancelled in that wait
leaves the left hand in the middle; started again from there, its first operation takes the right
hand to the middle, through the left one.
"""
from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app_functions.registry import full_catalog
from cell_runner import nodes
from cell_runner.bridge_nodes.common import run_bridge
from cell_runner.bridge_nodes.nextage_sim import declare_nextage_parameters
from cell_runner.ros_main import Outcome
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import Application, read_application
from node_transport.wire import machine_node_name
from robot_bridges.collision import scene_for

MIDDLE = '<param value="0.34,0.0,0.10,180deg,0,90deg"/>'
CROSSING = f"""<?xml version="1.0"?>
<application name="crossing" robot="nextage">
  <operation id="1"><right_arm><function name="move_to"><params>{MIDDLE}</params></function></right_arm></operation>
  <operation id="2"><right_arm><function name="move_to_joint_pose"><params><param value="initial"/></params></function></right_arm></operation>
  <operation id="3"><left_arm><function name="move_to"><params>{MIDDLE}</params></function></left_arm></operation>
  <operation id="4"><left_arm><function name="wait"><params><param value="30"/></params></function></left_arm></operation>
  <operation id="5"><left_arm><function name="move_to_joint_pose"><params><param value="initial"/></params></function></left_arm></operation>
</application>
"""
#: The index (1-based, as feedback counts) of the operation a cancel lands in: the 30 s wait.
WAIT_OPERATION = 4


def crossing_app(folder: Path) -> Application:
    path = folder / "crossing.xml"
    path.write_text(CROSSING)
    app, diagnostics = read_application(path, full_catalog())
    assert app is not None, diagnostics
    return app


@dataclass
class CollisionWatch:
    """Every ``joint_states`` sample checked with the Nextage's collision model: bodies that touch."""

    scene: Any = field(default_factory=lambda: scene_for(NEXTAGE_OPEN))
    samples: int = 0
    touching: list[str] = field(default_factory=list)

    def __call__(self, msg: Any) -> None:
        where = dict(zip(msg.name, msg.position))
        if not all(name in where for name in self.scene.joint_names):
            return
        self.samples += 1
        q = np.array([where[name] for name in self.scene.joint_names])
        for contact in self.scene.contacts(q):
            if contact.collision:
                self.touching.append(contact.describe(self.scene.margin))


#: Both hands to the middle at once: the dry run finds the collision from any start.
COLLIDING = f"""<?xml version="1.0"?>
<application name="colliding" robot="nextage">
  <operation id="1">
    <left_arm><function name="move_to"><params>{MIDDLE}</params></function></left_arm>
    <right_arm><function name="move_to"><params>{MIDDLE}</params></function></right_arm>
  </operation>
</application>
"""


def start_nextage_cell(transport: Any, speed: float = 20.0, **engine_parameters: Any) -> list[Any]:
    """The Nextage simulator's bridge, one machine per group and the engine as nodes of
    ``transport`` (rclpy or DDS), each running its executable's body: their tasks (cancel them)."""
    bridge = transport.create_node("nextage_sim_bridge", parameters={"speed": speed})
    tasks = [asyncio.ensure_future(run_bridge("nextage-sim", declare_nextage_parameters, bridge, Outcome()))]
    for group in NEXTAGE_OPEN.group_names:
        machine = transport.create_node(machine_node_name(group), parameters={"group": group})
        tasks.append(asyncio.ensure_future(nodes.run_group_machine(machine, Outcome())))
    engine = transport.create_node("execution_engine", parameters=engine_parameters)
    tasks.append(asyncio.ensure_future(nodes.run_engine(engine, Outcome())))
    return tasks
