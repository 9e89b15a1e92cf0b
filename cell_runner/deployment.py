"""The embedded deployment: engine, one machine per group and a bridge, as nodes of one process.

This is the default way to run (``python -m execution_engine run``) and the test bed: the
nodes are exactly those of a ROS 2 launch, talking only over the in-process transport, so
nothing here can lean on shared memory that a real deployment would not have.
"""
from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from cell_runner.libraries import APPLICATION_FUNCTIONS
from core_functions.cell_robots import CellRobotModel
from core_functions.robots import RobotModel
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.function_library import FunctionLibrary
from execution_engine.machine.group_machine import GroupMachine
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.port import ParameterValue, Transport
from robot_bridges.backend import RobotBackend
from robot_bridges.bridge_node import BridgeNode
from robot_bridges.cell_backend import CellBackend

log = logging.getLogger(__name__)


@dataclass
class Deployment:
    transport: Transport
    engine: ExecutionEngine
    machines: dict[str, GroupMachine]
    bridge: BridgeNode
    tasks: list[asyncio.Task[None]] = field(default_factory=list)
    #: Every bridge: one per robot of a mixed cell (``bridge`` is the first), else ``[bridge]``.
    bridges: list[BridgeNode] = field(default_factory=list)

    async def close(self) -> None:
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        for bridge in reversed(self.bridges or [self.bridge]):
            await bridge.close()
        for machine in self.machines.values():
            machine.close()
        await self.transport.shutdown()


async def deploy_local(
    clock: Clock,
    robot: RobotModel,
    backend: RobotBackend,
    *,
    machine_parameters: Mapping[str, ParameterValue] | None = None,
    engine_parameters: Mapping[str, ParameterValue] | None = None,
    bridge_parameters: Mapping[str, ParameterValue] | None = None,
    transport: LocalTransport | None = None,
    operators: bool = True,
    hold_for_operators: bool = False,
    library: FunctionLibrary = APPLICATION_FUNCTIONS,
) -> Deployment:
    """Start every node of a robot cell on one in-process transport.

    ``operators`` and ``hold_for_operators`` go to :class:`ExecutionEngine`: whether anyone can
    answer an alarm, and whether simulated time stands still while they are waited for.  ``library``:
    the functions applications may call (default: every library this program ships).
    """
    transport = transport or LocalTransport(clock)
    bridges: list[BridgeNode] = []
    try:
        for node_name, part in bridge_parts(backend):
            bridges.append(BridgeNode(transport.create_node(f"{node_name}_bridge", parameters=bridge_parameters), part))
            await bridges[-1].start()
    except BaseException:
        for started in reversed(bridges):
            await started.close()
        raise
    machines: dict[str, GroupMachine] = {}
    for group in robot.group_names:
        # a machine drives its group with its own robot's model (in a mixed cell: that robot's, not the cell's)
        member = robot.member_of(group) if isinstance(robot, CellRobotModel) else None
        names = {"cell_names": member.names.text()} if member is not None and not member.names.identity else {}
        params = {"group": group, "robot": member.model.name if member is not None else robot.name, **names, **(machine_parameters or {})}
        machines[group] = GroupMachine(transport.create_node(f"{group}_machine", parameters=params), library)
    engine = ExecutionEngine(
        transport.create_node("execution_engine", parameters=engine_parameters), library.catalog(None), operators=operators, hold_for_operators=hold_for_operators,
    )
    deployment = Deployment(transport, engine, machines, bridges[0], bridges=bridges)
    loop = asyncio.get_running_loop()
    for group, machine in machines.items():
        deployment.tasks.append(loop.create_task(_supervise(machine, group), name=f"{group} machine"))
    return deployment


def bridge_parts(backend: RobotBackend) -> list[tuple[str, RobotBackend]]:
    """Each bridge's node name and back end: one per robot of a mixed cell (named after the robot), else one."""
    if isinstance(backend, CellBackend):
        return [(_node_name(part.robot.name), part.backend) for part in backend.parts]
    return [(_node_name(backend.name), backend)]


def _node_name(name: str) -> str:
    return re.sub(r"\W+", "_", name).strip("_") or "robot"


async def _supervise(machine: GroupMachine, group: str) -> None:
    try:
        await machine.run()
    except asyncio.CancelledError:
        raise
    except Exception:  # noqa: BLE001 - GroupMachine.run only leaves by cancellation; log anything else
        log.exception("the %s machine stopped unexpectedly", group)
        raise
