"""The group machine node: one robot group's state machine on the transport.

Builds the machine from Table 2, connects it to its topics and services, and keeps it alive:
the machine's own task is supervised, so a defect inside a state does not kill the node
silently -- it is reported and the machine lands in ErrorHandling, waiting for a reset, exactly
as a robot fault would.

Topics (``/<group>/sm/...``): ``request`` in, ``result`` out, ``state`` (latched), ``status``
(every event), ``structure`` (latched); services ``pause``, ``resume``, ``stop``, ``reset``;
``/<group>/bridge/command`` out and ``feedback`` in; the coordination topic for barriers; the
engine's cell model (latched).
"""
from __future__ import annotations

import asyncio
import hashlib
import os
from pathlib import Path
from typing import Any

from core_functions.functions import SkillContext
from core_functions.cell_robots import CellNames, named_model
from core_functions.robots import find_robot
from core_functions.trajectory_store import TrajectoryStore
from execution_engine.function_library import FunctionLibrary
from execution_engine.machine.context import MachineConfig, MachineContext, Publishers
from execution_engine.machine.diagnostics import MachineDiagnostics
from execution_engine.machine.events import (
    EventQueue,
    FaultEvent,
    FeedbackEvent,
    OperatorSignal,
    RequestEvent,
    SyncEvent,
)
from execution_engine.machine.located import LocatedFramesPublisher
from execution_engine.machine.states import (
    ErrorHandlingState,
    PauseState,
    ReadyState,
    StopState,
    SyncState,
    WorkingState,
)
from execution_engine.machine.table import (
    ERROR_HANDLING,
    FINISH,
    PAUSE,
    READY,
    STOP,
    SYNC_STATES,
    TABLE_2,
    WORKING_STATES,
)
from execution_engine.smach import StateMachine, StructureInfo, TransitionRecord, UserData
from node_transport import codec, typed
from node_transport.carriage import TypedPublisher, subscribe
from node_transport.bounded import declare_bounded
from node_transport.msgs import Trigger, TriggerRequest, TriggerResponse
from node_transport.port import Node
from node_transport.qos import COMMANDS, EVENTS, LATCHED
from node_transport.wire import (
    ENGINE_CELL,
    MACHINE_SERVICES,
    SYNC_TOPIC,
    BridgeCommand,
    BridgeFeedback,
    CellSnapshot,
    FaultKind,
    SmRequest,
    SmResult,
    SmStatus,
    SmStructure,
    SyncMessage,
    TransitionSpec,
    bridge_topic,
    sm_service,
    sm_topic,
)

_VALID_IN = {
    "pause": (READY, *WORKING_STATES),
    "resume": (PAUSE,),
    "stop": (READY, *WORKING_STATES, PAUSE),
    "reset": (ERROR_HANDLING,),
}


def default_trajectory_db() -> str:
    """The per-user database a machine falls back to when nobody names one (it says so when it does)."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return str(Path(base) / "dual_arm_executive" / "trajectories.sqlite")


class GroupMachine:
    """One group's machine, its node wiring and its supervision.

    ``library`` gives the catalog and the functions class of the libraries the node's ``libraries``
    parameter chooses; the wiring hands it in, so a machine runs any function library."""

    def __init__(self, node: Node, library: FunctionLibrary) -> None:
        self.node = node
        self.clock = node.clock
        self.group = str(node.declare_parameter("group", "left_arm", "the robot group this machine drives"))
        robot_name = str(node.declare_parameter("robot", "nextage_open", "robot model (nextage_open, adept_viper_s850, kuka_kr)"))
        cell_names = str(node.declare_parameter(
            "cell_names", "", "how a cell of several robots names this robot's groups and joints (prefix=viper_;arm=inspector); '' = its own names",
        ))
        libraries = str(node.declare_parameter("libraries", "all", "comma-separated function libraries, or all"))
        db = str(node.declare_parameter(
            "trajectory_db", "", "SQLite file of recorded trajectories, best next to the application (APP.trajectories.sqlite); "
            "'' = the per-user default, with a warning"
        ))
        config = MachineConfig(
            bridge_timeout=declare_bounded(node, "bridge_timeout", MachineConfig.bridge_timeout, "how fast the bridge must acknowledge a command (s)"),
            primitive_timeout=declare_bounded(node, "primitive_timeout", MachineConfig.primitive_timeout, "longest a primitive may run (s)"),
            sync_timeout=declare_bounded(node, "sync_timeout", MachineConfig.sync_timeout, "how long partners may take to meet at a barrier (s)"),
        )
        self.robot = named_model(find_robot(robot_name), CellNames.parse(cell_names))
        if self.group not in self.robot.group_names:
            raise ValueError(f"{node.fully_qualified_name}: group {self.group!r} is not a group of {self.robot.name} ({', '.join(self.robot.group_names)})")
        chosen = None if libraries.strip() == "all" else [x.strip() for x in libraries.split(",") if x.strip()]
        if not db:
            db = default_trajectory_db()
            node.logger.warning(
                "%s: no trajectory_db given: trajectories are read from and recorded to %s in your home directory; "
                "set trajectory_db to keep them with the application", node.fully_qualified_name, db,
            )
        self.store = TrajectoryStore(db)
        skill_context = SkillContext(self.group, self.robot, None, self.store, self.clock.now)
        functions = library.functions_class(chosen)(skill_context)
        self.events = EventQueue(self.clock)
        g = self.group
        publishers = Publishers(
            result=TypedPublisher(node, SmResult, sm_topic(g, "result"), COMMANDS),
            status=TypedPublisher(node, SmStatus, sm_topic(g, "status"), EVENTS),
            state=node.create_publisher(typed.MachineStateMsg, sm_topic(g, "state"), LATCHED),
            bridge=TypedPublisher(node, BridgeCommand, bridge_topic(g, "command"), COMMANDS),
            sync=TypedPublisher(node, SyncMessage, SYNC_TOPIC, COMMANDS),
        )
        self._structure_pub = TypedPublisher(node, SmStructure, sm_topic(g, "structure"), LATCHED)
        self.ctx = MachineContext(
            group=g,
            node=node,
            robot=self.robot,
            catalog=library.catalog(chosen),
            functions=functions,
            events=self.events,
            publishers=publishers,
            config=config,
            feedback=subscribe(node, BridgeFeedback, bridge_topic(g, "feedback"), self._on_feedback, self._bad_feedback, COMMANDS, hand_over=True),
        )
        # requests and feedback only go on the event queue: taken as hand-overs (node_transport/local.py)
        subscribe(node, SmRequest, sm_topic(g, "request"), self._on_request, self._bad_request, COMMANDS, hand_over=True)
        subscribe(node, SyncMessage, SYNC_TOPIC, self._on_sync, self._bad_sync, COMMANDS)
        subscribe(node, CellSnapshot, ENGINE_CELL, self._on_cell, self._bad_cell, LATCHED)
        for command in MACHINE_SERVICES:
            node.create_service(Trigger, sm_service(g, command), lambda req, c=command: self._on_service(c, req))
        node.fault_handler = self._on_fault
        self._pause_pending_in: str | None = None  # the working state a pause was accepted in
        self.machine = self._build()
        self.userdata = UserData(primitive=None, resume_command=None, early_done=None, error=None, fault=None, stop_reason=None)
        self._diagnostics = MachineDiagnostics(node, self.ctx, lambda: self.userdata.get("error"))  # diagnostics, 1 Hz
        self._located = LocatedFramesPublisher(node, g)  # vision corrections -> the engine's tf_static

    # ----------------------------------------------------------------------------- build
    def _build(self) -> StateMachine:
        sm = StateMachine(self.group, (FINISH,), self.clock)
        ctx = self.ctx
        sm.add(READY, ReadyState(ctx), TABLE_2[READY])
        for name in WORKING_STATES:
            state = SyncState(name, ctx) if name in SYNC_STATES else WorkingState(name, ctx)
            sm.add(name, state, TABLE_2[name])
        sm.add(PAUSE, PauseState(ctx), TABLE_2[PAUSE])
        sm.add(STOP, StopState(ctx), TABLE_2[STOP])
        sm.add(ERROR_HANDLING, ErrorHandlingState(ctx), TABLE_2[ERROR_HANDLING])
        sm.set_initial(READY)
        sm.check()
        sm.add_observer(self)
        self._publish_structure(sm.structure())
        return sm

    # --------------------------------------------------------------------- introspection
    def _publish_structure(self, structure: StructureInfo) -> None:
        message = SmStructure(
            group=self.group,
            initial=structure.initial,
            states=(*structure.states, FINISH),
            transitions=tuple(TransitionSpec(s, o, t) for s, o, t in structure.transitions),
        )
        self._structure_pub.publish(message)

    def on_structure(self, structure: StructureInfo) -> None:
        """Structure is published once, when built (latched); nothing to do per run."""

    def on_enter(self, machine: str, state: str, t: float) -> None:
        if self.ctx.state_name != state:
            self._set_state(state)

    def on_transition(self, record: TransitionRecord) -> None:
        self.ctx.status("transition", from_state=record.source, to_state=record.target, signal=record.outcome, state=record.target)
        self._set_state(record.target)

    def _set_state(self, state: str) -> None:
        self._pause_pending_in = None
        self.ctx.state_name = state
        self.ctx.pub.state.publish(typed.machine_state(self.group, state, self.clock))
        self._diagnostics.update()

    @property
    def state(self) -> str:
        return self.ctx.state_name

    # ---------------------------------------------------------------------------- inputs
    def _on_request(self, request: SmRequest) -> None:
        self.events.put(RequestEvent(request))

    def _bad_request(self, error: codec.WireError) -> None:
        self.ctx.status("error", error=f"rejected request: {error}")
        self.node.logger.error("%s: %s", self.node.fully_qualified_name, error)

    def _on_feedback(self, feedback: BridgeFeedback) -> None:
        self.events.put(FeedbackEvent(feedback))

    def _bad_feedback(self, error: codec.WireError) -> None:
        self.events.put(FaultEvent("bridge feedback", str(error), FaultKind.PROTOCOL))

    def _on_sync(self, message: SyncMessage) -> None:
        if message.group == self.group:
            return
        self.ctx.record_sync(message)
        self.events.put(SyncEvent(message))

    def _bad_sync(self, error: codec.WireError) -> None:
        self.node.logger.error("%s: ignored sync message: %s", self.node.fully_qualified_name, error)

    def _bad_cell(self, error: codec.WireError) -> None:
        self.ctx.status("error", error=f"ignored cell model: {error}")

    def _on_cell(self, snapshot: CellSnapshot) -> None:
        self.ctx.set_cell(snapshot.index())
        self.store.cell_sha256 = hashlib.sha256(codec.encode(snapshot).encode()).hexdigest()  # stamped on what is recorded for it
        self._located.attach(self.ctx.cell)

    async def _on_service(self, command: str, request: TriggerRequest) -> TriggerResponse:
        state = self.ctx.state_name
        pausing = self._pause_pending_in == state  # accepted, not yet landed: signals are queued in order
        valid = state in _VALID_IN[command]
        if command == "pause" and ((state == READY and self.ctx.hold) or pausing):
            valid = False
        if command == "resume" and ((state == READY and self.ctx.hold) or pausing):
            valid = True
        if not valid:
            return Trigger.Response(False, f"{self.group}: cannot {command} in {state}")
        self._pause_pending_in = state if command == "pause" and state in WORKING_STATES else None
        self.events.put(OperatorSignal(command, self.node.resolve(sm_service(self.group, command))))  # type: ignore[arg-type]
        return Trigger.Response(True, f"{self.group}: {command} accepted in {state}")

    def _on_fault(self, where: str, error: BaseException) -> None:
        self.node.logger.error("%s: fault in %s: %r", self.node.fully_qualified_name, where, error)
        self.events.put(FaultEvent(where, f"{type(error).__name__}: {error}"))

    # ----------------------------------------------------------------------------- run
    async def run(self) -> None:
        """Run the machine for as long as the node lives; Finish waits for the next application."""
        self._set_state(READY)
        initial = READY
        while True:
            try:
                self.machine.set_initial(initial)
                await self.machine.execute(self.userdata)
                self._set_state(FINISH)
                await self._wait_for_restart()
                initial = READY
            except asyncio.CancelledError:
                raise
            except Exception as error:  # noqa: BLE001 - supervised: reported, then ErrorHandling
                self.node.logger.exception("%s: machine fault", self.node.fully_qualified_name)
                self.ctx.status("error", error=f"internal fault: {type(error).__name__}: {error}")
                self.userdata["error"] = f"internal fault: {type(error).__name__}: {error}"
                self.userdata["fault"] = FaultKind.INTERNAL
                initial = ERROR_HANDLING

    async def _wait_for_restart(self) -> None:
        while True:
            event = await self.events.get()
            if isinstance(event, RequestEvent) and event.request.kind == "execute":
                self.events.put_back(event)
                return

    def close(self) -> None:
        self._diagnostics.close()
        self.store.close()
