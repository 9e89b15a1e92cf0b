"""A group machine's side of the interference zones: ask before a motion enters one, say when it left.

The zones come with the engine's cell snapshot (frames of kind ``zone``: app_model/zones.py).
Before the machine hands a motion to its working state it asks :meth:`ZoneGate.admits`: a motion
whose end lies in a zone the group does not hold yet waits in Ready (pause, stop and ``end`` work
as ever) until the engine grants the zone (execution_engine/engine/zones.py); the announcement is
repeated every ``resend_interval``, as at a barrier, so a lost message costs a moment, never the
run.  Where a motion ends is known before it starts for a Cartesian move (its target) and a
relative one (from where the last motion left the TCP); for the others (joint moves, trajectories)
it is not, and they wait for every zone their call works in (a frame it names lies inside), to
be safe.  After each motion (:meth:`moved`) the TCP the bridge reports -- else the target --
says whether the group is still inside; once outside it tells the engine it left, so the other
arm gets in as soon as this one is out, not when its function ends.  Synchronised motions
(master/slave, full body) are not gated: the partners move as one.
"""
from __future__ import annotations

from typing import Protocol

from core_functions.cell_index import CellIndex
from core_functions.geometry import Pose
from core_functions.primitives import ExecuteTrajectory, MotionResult, MoveCartesian, MoveJoints, MoveRelative, RecordTrajectory
from execution_engine.app_model.zones import ENGINE, ZONE_KIND, inside_box, zone_key
from node_transport.clock import Clock
from execution_engine.machine.function_run import FunctionRun
from node_transport.wire import SyncMessage

_MOVES = (MoveJoints, MoveCartesian, MoveRelative, RecordTrajectory, ExecuteTrajectory)
Box = tuple[Pose, tuple[float, float, float]]


class Resending(Protocol):
    """How often an unanswered announcement is repeated (machine/context.py's MachineConfig)."""

    @property
    def resend_interval(self) -> float: ...


class GateMachine(Protocol):
    """What the gate reads of its group machine (machine/context.py's MachineContext), and how it announces."""

    @property
    def cell(self) -> CellIndex | None: ...
    @property
    def run(self) -> FunctionRun | None: ...
    @property
    def clock(self) -> Clock: ...
    @property
    def config(self) -> Resending: ...
    @property
    def sync_board(self) -> dict[str, dict[str, SyncMessage]]: ...

    def send_sync(self, key: str, event: str) -> None: ...


class ZoneGate:
    """Which zones this group holds during its current function, and the asking for more."""

    def __init__(self, ctx: GateMachine) -> None:
        self.ctx = ctx
        self.tcp: Pose | None = None  # where the last motion left the TCP (world)
        self._request = ""  # the function (request id) the state below belongs to
        self.held: set[str] = set()
        self._asked_at: dict[str, float] = {}

    def _zones(self) -> dict[str, Box]:
        cell = self.ctx.cell
        if cell is None:
            return {}
        boxes: dict[str, Box] = {}
        for name, frame in cell.frame_map.items():
            if frame.kind == ZONE_KIND:
                size = tuple(float(x) for x in getattr(frame, "attributes", {}).get("size", "0 0 0").split())
                boxes[name] = (frame.pose, size)  # type: ignore[assignment]
        return boxes

    def _current(self) -> None:
        run = self.ctx.run
        request = run.request.id if run is not None else ""
        if request != self._request:
            self._request, self.held, self._asked_at = request, set(), {}

    def _target(self, primitive: object) -> tuple[float, float, float] | None:
        if isinstance(primitive, MoveCartesian):
            return primitive.target.position
        if isinstance(primitive, MoveRelative) and self.tcp is not None:
            delta = primitive.delta
            moved = self.tcp.compose(delta) if primitive.reference == "tool" else self.tcp.translated(*delta.position)
            return moved.position
        return None

    def _call_zones(self, zones: dict[str, Box]) -> set[str]:
        """The zones a frame named by the running call lies in."""
        run, cell = self.ctx.run, self.ctx.cell
        if run is None or cell is None:
            return set()
        names = [p for text in run.request.params for p in text.replace(",", " ").split() if cell.has_frame(p) and p != "world"]
        return {z for z, (pose, size) in zones.items() for n in names if cell.frame_kind(n) != ZONE_KIND and inside_box(pose, size, cell.pose(n).position)}

    def entering(self, primitive: object) -> set[str]:
        """The zones ``primitive`` ends in (every zone of the call for a move whose end is not known)."""
        if not isinstance(primitive, _MOVES):
            return set()
        zones = self._zones()
        if not zones:
            return set()
        target = self._target(primitive)
        if target is None:
            return self._call_zones(zones)
        return {z for z, (pose, size) in zones.items() if inside_box(pose, size, target)}

    def admits(self, primitive: object) -> bool:
        """Whether ``primitive`` may start now; if not, the engine has been asked (again, when due)."""
        self._current()
        missing = sorted(self.entering(primitive) - self.held)
        if not missing:
            return True
        ctx = self.ctx
        now = ctx.clock.now()
        for zone in missing:
            key = zone_key(zone, self._request)
            answer = ctx.sync_board.get(key, {}).get(ENGINE)
            if answer is not None and answer.event == "done":
                self.held.add(zone)
                self._asked_at.pop(zone, None)  # granted: no more announcements due (else Ready would wake at once, for ever)
                continue
            if now >= self._asked_at.get(zone, -1e18) + ctx.config.resend_interval:
                ctx.send_sync(key, "arrived")
                self._asked_at[zone] = now
        return not (set(missing) - self.held)

    def wake_in(self) -> float:
        """Run seconds until the next announcement is due."""
        if not self._asked_at:
            return self.ctx.config.resend_interval
        due = min(self._asked_at.values()) + self.ctx.config.resend_interval
        return max(0.0, due - self.ctx.clock.now())

    def moved(self, primitive: object, result: object) -> None:
        """A primitive ended well: where the TCP is now, and the zones it has left."""
        if not isinstance(primitive, _MOVES):
            return
        self._current()
        tcp = result.tcp if isinstance(result, MotionResult) and result.tcp is not None else None
        target = self._target(primitive)
        if tcp is None and target is not None:
            tcp = Pose.from_xyz_rpy(*target)
        self.tcp = tcp
        if tcp is None or not self.held:
            return
        zones = self._zones()
        for zone in sorted(self.held):
            pose, size = zones.get(zone, (None, None))
            if pose is None or not inside_box(pose, size, tcp.position):  # type: ignore[arg-type]
                self.held.discard(zone)
                key = zone_key(zone, self._request)
                self.ctx.send_sync(key, "left")
                self.ctx.sync_board.get(key, {}).pop(ENGINE, None)  # back into the zone later: ask again
