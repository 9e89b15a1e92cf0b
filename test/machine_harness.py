"""A test bench for group machines: real machines and bridge on the local transport, a fake engine.

The "engine" here is just a node that publishes requests and calls services, so a test can
drive a machine into any state of Table 2 and watch the status topic for the transitions.
"""
from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

from scripted_backend import ScriptedBackend

from cell_runner.libraries import APPLICATION_FUNCTIONS
from core_functions.cell_index import CellFrame
from core_functions.geometry import Pose
from core_functions.robots import NEXTAGE_OPEN, RobotModel
from execution_engine.machine.group_machine import GroupMachine
from node_transport import codec, typed
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.msgs import Trigger, TriggerResponse
from node_transport.qos import COMMANDS, EVENTS, LATCHED
from node_transport.wire import ENGINE_CELL, CellSnapshot, SmRequest, SmResult, SmStatus, sm_service, sm_topic
from robot_bridges.bridge_node import BridgeNode

CELL = CellSnapshot(
    name="test_cell",
    frames=(
        CellFrame("hole_1", Pose.from_xyz_rpy(0.35, 0.0, 0.05, 3.14159265, 0, 0), kind="hole", attributes={"diameter": "0.0048"}),
        CellFrame("above", Pose.from_xyz_rpy(0.35, 0.0, 0.15, 3.14159265, 0, 0)),
    ),
)


@dataclass
class Harness:
    clock: Clock
    robot: RobotModel = NEXTAGE_OPEN
    durations: dict[str, float] = field(default_factory=dict)
    parameters: dict[str, Any] = field(default_factory=dict)
    backend_class: type[ScriptedBackend] = ScriptedBackend  # a subclass scripts more (a slow measurement, say)

    async def start(self) -> Harness:
        self.transport = LocalTransport(self.clock)
        self.backend = self.backend_class(self.clock, self.robot, self.durations)
        self.bridge = BridgeNode(self.transport.create_node("bridge"), self.backend)
        await self.bridge.start()
        self.engine = self.transport.create_node("fake_engine")
        self.cell_pub = self.engine.create_publisher(typed.CellSnapshotMsg, ENGINE_CELL, LATCHED)
        self.cell_pub.publish(typed.to_msg(CELL, self.clock))
        self.machines: dict[str, GroupMachine] = {}
        self.status: dict[str, list[dict[str, Any]]] = {}
        self.results: dict[str, SmResult] = {}
        self._request_pubs = {}
        loop = asyncio.get_running_loop()
        self.tasks = []
        for group in self.robot.group_names:
            params = {"group": group, "robot": self.robot.name, "trajectory_db": ":memory:", **self.parameters}
            machine = GroupMachine(self.transport.create_node(f"{group}_machine", parameters=params), APPLICATION_FUNCTIONS)
            self.machines[group] = machine
            self.status[group] = []
            self.engine.create_subscription(
                typed.MachineStatusMsg, sm_topic(group, "status"),
                lambda m, g=group: self.status[g].append(codec.to_primitive(typed.from_msg(SmStatus, m, self.clock))), EVENTS,
            )
            self.engine.create_subscription(typed.MachineResultMsg, sm_topic(group, "result"), self._on_result, COMMANDS)
            self._request_pubs[group] = self.engine.create_publisher(typed.MachineRequestMsg, sm_topic(group, "request"), COMMANDS)
            self.tasks.append(loop.create_task(machine.run()))
        self._clients = {
            (g, c): self.engine.create_client(Trigger, sm_service(g, c)) for g in self.robot.group_names for c in ("pause", "resume", "stop", "reset")
        }
        self._next = 0
        await self.clock.sleep(0)
        return self

    async def close(self) -> None:
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        await self.bridge.close()

    def _on_result(self, msg: Any) -> None:
        result = typed.from_msg(SmResult, msg, self.clock)
        self.results[result.id] = result

    # ---------------------------------------------------------------------------- driving
    def send(self, group: str, function: str, *params: str, operation: str = "1", sync: str = "", partners: tuple[str, ...] = ()) -> str:
        self._next += 1
        request_id = f"req-{self._next}"
        request = SmRequest(id=request_id, operation=operation, function=function, params=params, sync=sync, partners=partners)
        self._request_pubs[group].publish(typed.to_msg(request, self.clock))
        return request_id

    def send_raw(self, group: str, msg: Any) -> None:
        self._request_pubs[group].publish(msg)

    def end(self, group: str) -> None:
        self._next += 1
        self._request_pubs[group].publish(typed.to_msg(SmRequest(id=f"end-{self._next}", kind="end"), self.clock))

    async def service(self, group: str, command: str) -> TriggerResponse:
        response: TriggerResponse = await self._clients[(group, command)].call(Trigger.Request(), timeout=5.0)
        return response

    async def result(self, request_id: str, timeout: float = 60.0) -> SmResult:
        deadline = self.clock.now() + timeout
        while request_id not in self.results:
            if self.clock.now() > deadline:
                raise AssertionError(f"no result for {request_id} within {timeout} s")
            await self.clock.sleep(0.01)
        return self.results[request_id]

    async def until_state(self, group: str, state: str, timeout: float = 30.0) -> None:
        deadline = self.clock.now() + timeout
        while self.machines[group].state != state:
            if self.clock.now() > deadline:
                raise AssertionError(f"{group} did not reach {state} within {timeout} s (is in {self.machines[group].state})")
            await self.clock.sleep(0.005)

    def transitions(self, group: str) -> list[tuple[str, str, str]]:
        return [(e["from"], e["signal"], e["to"]) for e in self.status[group] if e["event"] == "transition"]

    def events(self, group: str, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.status[group] if e["event"] == kind]
