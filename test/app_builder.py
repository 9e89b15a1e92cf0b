"""Build Application objects directly (no XML) for engine tests, and run them on a scripted cell."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scripted_backend import ScriptedBackend

from cell_runner.deployment import Deployment, deploy_local
from core_functions.robots import NEXTAGE_OPEN, RobotModel
from execution_engine.app_model.model import Application, Call, ErrorPolicy, Operation
from execution_engine.engine.report import RunReport
from node_transport import codec, typed
from node_transport.clock import Clock
from node_transport.msgs import Trigger
from node_transport.qos import EVENTS
from node_transport.wire import ENGINE_STATUS, EngineStatus, SmStatus, engine_service, sm_topic

OpSpec = Mapping[str, Sequence[str]]  # group -> (function, *params)


def make_app(operations: Sequence[OpSpec], policy: ErrorPolicy | None = None, robot: RobotModel = NEXTAGE_OPEN) -> Application:
    ops = []
    for index, spec in enumerate(operations, start=1):
        calls = {g: Call(g, "wait", ("0",), implicit=True) for g in robot.group_names}
        for group, (function, *params) in spec.items():
            calls[group] = Call(group, function, tuple(params))
        ops.append(Operation(str(index), None, index, 1, calls))
    return Application("test_app", Path("test_app.xml"), robot, None, policy or ErrorPolicy(), tuple(ops))


@dataclass
class Cell:
    """A scripted cell: deployment + event recording + operator service clients."""

    clock: Clock
    robot: RobotModel = NEXTAGE_OPEN
    durations: dict[str, float] = field(default_factory=dict)
    engine_parameters: dict[str, Any] = field(default_factory=dict)

    async def start(self) -> Cell:
        self.backend = ScriptedBackend(self.clock, self.robot, self.durations)
        self.deployment: Deployment = await deploy_local(
            self.clock, self.robot, self.backend, machine_parameters={"trajectory_db": ":memory:"}, engine_parameters=self.engine_parameters
        )
        node = self.deployment.transport.create_node("test_operator")
        self.events: list[dict[str, Any]] = []
        self.engine_states: list[dict[str, Any]] = []
        for group in self.robot.group_names:
            node.create_subscription(
                typed.MachineStatusMsg, sm_topic(group, "status"), lambda m: self.events.append(codec.to_primitive(typed.from_msg(SmStatus, m, self.clock))), EVENTS
            )
        node.create_subscription(
            typed.EngineStatusMsg, ENGINE_STATUS, lambda m: self.engine_states.append(codec.to_primitive(typed.from_msg(EngineStatus, m, self.clock))), EVENTS
        )
        self.node = node
        self._clients = {c: node.create_client(Trigger, engine_service(c)) for c in ("start", "pause", "resume", "stop", "step", "reset")}
        return self

    async def operator(self, command: str) -> Any:
        return await self._clients[command].call(Trigger.Request(), timeout=5.0)

    async def run(self, app: Application) -> RunReport:
        try:
            return await self.deployment.engine.run(app)
        finally:
            await self.deployment.close()

    def functions(self, group: str) -> list[tuple[str, str, float, float]]:
        """(operation, function, t_start, t_end) of each function the group ran."""
        starts = {e["request_id"]: e for e in self.events if e["event"] == "function_start" and e["group"] == group}
        out = []
        for end in (e for e in self.events if e["event"] == "function_end" and e["group"] == group):
            start = starts[end["request_id"]]
            out.append((end["operation"], end["function"], start["t"], end["t"]))
        return out
