"""What the states of one group machine share: its node, its function run, its links.

States are small because everything they do to the outside world goes through here:
publishing status and results, sending bridge commands, starting and finishing functions, the
barrier board of synchronised motions.  One context per machine; states hold no other state.
"""
from __future__ import annotations

import asyncio
import itertools
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from core_functions.catalog import BindContext, Catalog, FunctionSpec, ParamError, ParamType
from core_functions.cell_index import CellIndex
from core_functions.functions import CoreFunctions
from core_functions.primitives import Primitive
from core_functions.robots import RobotModel
from node_transport.clock import Clock
from execution_engine.machine.bridge_watch import BridgeWatch
from execution_engine.machine.events import EventQueue
from execution_engine.machine.function_run import FunctionRun, SkillError
from execution_engine.machine.rebase import RelativeGoals
from execution_engine.machine.zone_gate import ZoneGate
from node_transport import codec
from node_transport.carriage import TypedPublisher
from node_transport.port import Node, Publisher, Subscription, wait_until_matched
from node_transport.wire import BridgeCommand, FaultKind, SmRequest, SmResult, SmStatus, SyncMessage


_KEPT_BINDINGS = 256
#: parameter types bound from their text and the robot alone (the others read the cell model)
_CELL_FREE = frozenset({ParamType.NUMBER, ParamType.INTEGER, ParamType.BOOLEAN, ParamType.TEXT, ParamType.CHOICE, ParamType.NAME, ParamType.JOINTS})
_SCALARS = (float, int, str, bool, type(None))


def _immutable(value: Any) -> bool:
    return type(value) in _SCALARS or (type(value) is tuple and all(type(v) in _SCALARS for v in value))


@dataclass(frozen=True)
class MachineConfig:
    """Bounds of every wait of the machine, in run seconds."""

    bridge_timeout: float = 5.0  # a bridge must acknowledge a command this fast
    primitive_timeout: float = 600.0  # no primitive runs longer than this
    sync_timeout: float = 30.0  # partners must meet at a barrier within this

    @property
    def resend_interval(self) -> float:
        """A command not acknowledged by then is sent again with its id (the bridge runs it once);
        an announcement at a barrier is repeated as often."""
        return min(0.5, self.bridge_timeout / 4)


@dataclass
class Publishers:
    result: TypedPublisher[SmResult]
    status: TypedPublisher[SmStatus]
    state: Publisher[Any]  # typed.MachineStateMsg
    bridge: TypedPublisher[BridgeCommand]
    sync: TypedPublisher[SyncMessage]


class MachineContext:
    """Shared by every state of one group machine."""

    def __init__(
        self,
        *,
        group: str,
        node: Node,
        robot: RobotModel,
        catalog: Catalog,
        functions: CoreFunctions,
        events: EventQueue,
        publishers: Publishers,
        config: MachineConfig,
        feedback: Subscription[Any] | None = None,
    ) -> None:
        self.group = group
        self.node = node
        self.clock: Clock = node.clock
        self.robot = robot
        self.catalog = catalog
        self.functions = functions
        self.events = events
        self.pub = publishers
        self.config = config
        self.run: FunctionRun | None = None
        self.hold = False  # paused while in Ready: the next primitive waits for resume
        self.active_command: str | None = None  # the bridge command a working state is running
        self.sync_board: dict[str, dict[str, SyncMessage]] = {}
        self.sync_key: str | None = None  # the barrier this group has announced itself at
        self.sync_sent: str | None = None  # the barrier whose command this leader has sent
        self._ids = itertools.count(1)
        self._session = uuid.uuid4().hex[:6]
        self.state_name = "Ready"
        self._feedback = feedback
        self.bridge_watch = BridgeWatch(node, feedback)  # a working state's check that the bridge is alive
        self._bridge_linked = False  # both directions to the bridge have matched
        self._sent: dict[str, BridgeCommand] = {}  # unacknowledged bridge commands, for resending
        self.cell_arrived = asyncio.Event()
        self.zones = ZoneGate(self)  # interference zones: ask before a motion enters one
        self.goals = RelativeGoals()  # the goals relative moves resolved to: a retry re-bases them (machine/rebase.py)
        self._bound: dict[tuple[str, tuple[str, ...]], tuple[FunctionSpec, tuple[Any, ...]]] = {}  # requests' params, bound

    # --------------------------------------------------------------------------- identity
    def new_id(self) -> str:
        return f"{self.group}-{self._session}-{next(self._ids)}"

    @property
    def cell(self) -> CellIndex | None:
        return self.functions.ctx.cell

    def set_cell(self, cell: CellIndex) -> None:
        self.functions.ctx.cell = cell
        self.cell_arrived.set()

    async def wait_for_cell(self, name: str) -> str | None:
        """The request was made for cell ``name``: wait (bounded) until the engine's latched cell
        model has arrived; the problem when it did not."""
        deadline = self.clock.now() + self.config.bridge_timeout
        while self.cell is None or self.cell.name != name:
            remaining = deadline - self.clock.now()
            if remaining <= 0:
                have = "no cell model" if self.cell is None else f"cell {self.cell.name!r}"
                return f"the cell model {name!r} did not arrive within {self.config.bridge_timeout:g} s (have {have})"
            self.cell_arrived.clear()
            try:
                await self.clock.wait_for(self.cell_arrived.wait(), remaining)
            except asyncio.TimeoutError:
                continue
        return None

    # ---------------------------------------------------------------------------- publish
    @property
    def watched(self) -> bool:
        """Whether anyone reads the status events: a state builds what only they need only then."""
        return self.pub.status.get_subscription_count() > 0

    def status(self, event: str, **fields: Any) -> None:
        """Publish one status event (the trace and the viewers are built from these)."""
        if self.pub.status.get_subscription_count() == 0:
            return
        run = self.run
        defaults: dict[str, Any] = {}
        if run is not None:
            defaults = {"operation": run.request.operation, "function": run.request.function, "request_id": run.request.id}
        if "result" in fields and fields["result"] is not None:
            fields["result"] = codec.to_primitive(fields["result"])
        values = {"state": self.state_name, **defaults, **fields}
        self.pub.status.publish(SmStatus(group=self.group, event=event, t=self.clock.now(), **values))  # type: ignore[arg-type]

    async def link_bridge(self) -> str | None:
        """Wait (bounded) until the command topic and the feedback topic have matched the bridge:
        over DDS a command published before discovery is lost.  The problem, or None."""
        if self._bridge_linked:
            return None
        endpoints: list[Any] = [self.pub.bridge] + ([self._feedback] if self._feedback is not None else [])
        if not await wait_until_matched(self.clock, endpoints, self.config.bridge_timeout):
            topic = self.node.resolve(self.pub.bridge.topic)
            return f"timeout: no bridge subscribed to {topic} (or publishes feedback) within {self.config.bridge_timeout:g} s"
        self._bridge_linked = True
        return None

    def send_bridge(self, op: str, primitive: Primitive | None = None, command_id: str | None = None) -> str:
        """Publish a bridge command; returns its id (feedback carries the same id)."""
        cid = command_id or self.new_id()
        command = BridgeCommand(id=cid, group=self.group, op=op, primitive=primitive)  # type: ignore[arg-type]
        self._sent[cid] = command
        if len(self._sent) > 16:  # only the newest few can still be waiting for their answer
            del self._sent[next(iter(self._sent))]
        self.pub.bridge.publish(command)
        return cid

    def resend_bridge(self, command_id: str) -> None:
        """The same command again, same id: the bridge runs an id once and repeats its last answer."""
        command = self._sent.get(command_id)
        if command is not None:
            self._bridge_linked = False  # seen unanswered: check the link again before the next one
            self.pub.bridge.publish(command)

    def acknowledged(self, command_id: str) -> None:
        self._sent.pop(command_id, None)

    def send_sync(self, key: str, event: str, error: str | None = None, fault: FaultKind | None = None) -> None:
        """Announce at a barrier; a failure carries its kind, so the partners report the same one."""
        message = SyncMessage(group=self.group, key=key, event=event, state=self.state_name, t=self.clock.now(), error=error, fault=fault)  # type: ignore[arg-type]
        self.record_sync(message)
        self.pub.sync.publish(message)

    def record_sync(self, message: SyncMessage) -> None:
        self.sync_board.setdefault(message.key, {})[message.group] = message
        if len(self.sync_board) > 64:  # keys of finished barriers: keep the newest only
            for stale in list(self.sync_board)[:-64]:
                del self.sync_board[stale]

    # ------------------------------------------------------------------------- functions
    def start_function(self, request: SmRequest) -> str | None:
        """Bind and start a requested function; returns an error text when it cannot start."""
        spec = self.catalog.get(request.function)
        if spec is None:
            return f"unknown function {request.function!r}{self.catalog.suggest(request.function)}"
        args = self._bound_args(spec, request.params)
        if args is None:
            try:
                args = spec.bind(request.params, BindContext(self.robot, self.group, self.cell))
            except ParamError as error:
                return f"{request.function}: {error.message}"
            except KeyError as error:  # a group unknown to the robot
                return f"{request.function}: {error}"
            self._keep_bound(spec, request.params, args)
        method: Callable[..., Any] = getattr(self.functions, spec.method)
        self.goals.begin(request)
        run = FunctionRun(request, spec, method(*args), self.clock.now())
        self.run = run
        self.status("function_start")
        try:
            run.start()
        except SkillError as error:
            self.finish_function("aborted", str(error), error.fault)
            return None
        return None

    def _bound_args(self, spec: FunctionSpec, params: tuple[str, ...]) -> list[Any] | None:
        """The arguments ``params`` bound to before for ``spec``, if kept: an application calls the
        same function with the same texts again and again (set_speed 0.5, a gripper's open)."""
        kept = self._bound.get((spec.name, params))
        return list(kept[1]) if kept is not None and kept[0] is spec else None

    def _keep_bound(self, spec: FunctionSpec, params: tuple[str, ...], args: list[Any]) -> None:
        """Keep what binding gave when it read nothing but the texts and the robot (no cell model: its
        frames can change) and nothing can change it (numbers, texts, tuples of them); 256 calls at most."""
        if all(p.type in _CELL_FREE for p in spec.params) and all(_immutable(a) for a in args):
            if len(self._bound) >= _KEPT_BINDINGS:
                del self._bound[next(iter(self._bound))]
            self._bound[(spec.name, params)] = (spec, tuple(args))

    def finish_function(self, outcome: str, error: str | None = None, fault: FaultKind | None = None) -> None:
        """Close the current function and send its result (with the fault's kind) to the engine."""
        run = self.run
        if run is None:
            return
        if not run.finished:
            run.close()
        self.status("function_end", outcome=outcome, error=error, count=run.started)
        self.send_result(run.request, outcome, error, fault, t_start=run.t_start, primitives=run.started)
        self.run = None

    def send_result(
        self,
        request: SmRequest,
        outcome: str,
        error: str | None,
        fault: FaultKind | None = None,
        *,
        t_start: float | None = None,
        primitives: int = 0,
    ) -> None:
        now = self.clock.now()
        result = SmResult(
            id=request.id,
            group=self.group,
            outcome=outcome,  # type: ignore[arg-type]
            operation=request.operation,
            function=request.function,
            error=error,
            fault=fault,
            t_start=now if t_start is None else t_start,
            t_end=now,
            primitives=primitives,
        )
        self.pub.result.publish(result)
