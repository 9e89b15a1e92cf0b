"""The station's jog: one back end of its own, on a thread and loop of its own, on the wall clock.

A jog is a person holding a button, so it runs in real time whatever ``--speed`` the station's runs use,
and on its own loop so that planning a leg never holds up the pages' feeds (and a page's heartbeat is never
held up by a leg).  The back end is made as a run's would be (``run``'s options: ``--robot``,
``--backend-option``, a V+ controller's address) for the application the page has open, the first time the
jog panel opens, and kept between jogs; it is closed before a run starts (a controller takes one
connection) and when the station stops.

The safety stop latches here too: raised from the page it stops any jog at once and refuses jogging until
it is cleared through the station's confirmed action.
"""
from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable, Coroutine
from concurrent.futures import Future
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

from core_functions.geometry import Pose
from execution_engine.app_model import Application
from node_transport.clock import Clock, real_clock
from operator_station.jog import JogRequest, Jogger, JogSettings, JogState, parse_request
from robot_bridges import registry
from robot_bridges.backend import BackendOptions, RobotBackend
from robot_bridges.collision import cell_boxes, scene_for

log = logging.getLogger(__name__)
T = TypeVar("T")

#: s the page's thread waits for the jog's loop to answer.
ANSWER_TIMEOUT = 10.0
#: s the station's stop waits for the jog to stop and its back end to close, then for its thread: SIGTERM ends
#: the station within 2 s.
CLOSE_TIMEOUT = 0.5
#: Told of each jog's start (or refusal by the jog's checks) and of each stop, on the jog's loop in the order they
#: happen: (the owner that holds the button, what, ok, the one-line answer, details) -- the audit's hook.
JogNote = Callable[[object | None, str, bool, str, dict[str, Any]], None]
#: Why a jog stopped, for the audit: the first of these its stop reason contains (else "stopped by a check").
CAUSES = (("jog released", "released"), ("no heartbeat", "heartbeat lapsed"), ("connection closed", "connection dropped"),
          ("safety stop", "safety stop"), ("collision", "refused by the collision check"), ("limit", "refused by a limit"),
          ("another jog button", "another button pressed"), ("a run starts", "released for a run"),
          ("the station stops", "the station stops"), ("another application", "the jog panel reopened"), ("message", "a bad message"))


def stop_cause(reason: str) -> str:
    """The short cause of a jog's stop reason (the reasons are this package's own lines)."""
    return next((cause for key, cause in CAUSES if key in reason), "stopped by a check")


@dataclass(frozen=True)
class JogTarget:
    """What the jog's back end was made for: a new one is made when any of it changes."""

    backend: str
    robot: str
    cell: str
    options: str


class JogStation:
    """At most one jog back end and one jog at a time; every method but the constructor from the server's loop."""

    def __init__(self, settings: JogSettings = JogSettings()) -> None:
        self.settings = settings
        self.safety = False  # the station's safety stop, latched until its confirmed clear
        #: The pages' sockets, each told of every change on its own loop.
        self.listeners: list[tuple[asyncio.AbstractEventLoop, Callable[[dict[str, Any]], None]]] = []
        self.owner: object | None = None  # the socket whose button holds the jog going on
        self.app: Application | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._clock: Clock | None = None
        self._backend: RobotBackend | None = None
        self._jogger: Jogger | None = None
        self._target: JogTarget | None = None
        self.note: JogNote | None = None  # the audit's hook (operator_station/jog_routes.py)
        self._moving = False  # whether the last change told was of a moving jog (a stop is its end)

    # ------------------------------------------------------------------ the back end
    @property
    def ready(self) -> bool:
        return self._jogger is not None

    @property
    def state(self) -> JogState:
        return self._jogger.state if self._jogger is not None else JogState()

    async def open(self, app: Application, backend: str, options: BackendOptions) -> dict[str, Any]:
        """The jog for ``app``'s robot on back end ``backend`` (made now unless it is the one made last)."""
        target = JogTarget(backend, app.robot.name, str(app.cell.path if app.cell is not None else ""), repr(options))
        if self._target != target or self._jogger is None:
            await self.release("the jog panel opened on another application")
            await self._on_loop(lambda: self._make(app, backend, options))
            self._target = target
        self.app = app
        return await self._on_loop(lambda: _async(self._description))

    async def _make(self, app: Application, backend: str, options: BackendOptions) -> None:
        assert self._clock is not None
        made = await registry.create_backend(backend, self._clock, options)
        await made.start()
        snapshot = app.cell.to_snapshot(app.robot) if app.cell is not None else None
        if snapshot is not None:
            made.set_cell(snapshot)
        try:
            scene = scene_for(app.robot, margin=self.settings.clearance)
            if snapshot is not None:
                scene.set_cell(cell_boxes(snapshot))
        except KeyError:  # a robot without a collision model: the back end's own checks only
            scene = None
        cell = app.cell
        self._backend = made
        self._jogger = Jogger(made, self._clock, app.robot, self.settings, frames=cell.pose if cell is not None else None,
                              scene=scene, on_change=self._tell)

    def _description(self) -> dict[str, Any]:
        assert self._jogger is not None and self._backend is not None and self.app is not None
        groups = {}
        for group in self.app.robot.group_names:
            limits = self._backend.joint_limits(group)
            groups[group] = {"joints": list(self.app.robot.group(group).joint_names), "tcp": self._backend.tcp_pose(group) is not None,
                             "lower": list(limits.lower) if limits else None, "upper": list(limits.upper) if limits else None}
        if not self._jogger.moving and not self._jogger.state.joints:  # a fresh jog: where the first arm is
            self._jogger.observe(next((g for g in groups if groups[g]["tcp"]), self.app.robot.group_names[0]))
        cell = self.app.cell
        return {"backend": self._backend.name, "groups": groups, "frames": sorted(cell.frames) if cell is not None else [],
                "speed": round(self.settings.speed * 100, 3), "cartesian_speed": round(self.settings.cartesian_speed * 1000, 3),
                "lease": self.settings.lease, "period": self._jogger.period, "holds_within_motion": self._backend.holds_within_motion,
                "state": self._jogger.state.to_json()}

    async def release(self, reason: str) -> None:
        """Stop any jog and close the back end (a run is about to start, or the station ends)."""
        if self._jogger is None:
            return
        jogger, backend = self._jogger, self._backend
        self._jogger, self._backend, self._target = None, None, None

        async def close() -> None:
            await jogger.stop(reason)
            if backend is not None:
                await backend.close()

        await self._on_loop(close)

    def close(self) -> None:
        """End the jog's loop (from any thread; the station is going away): the back end first."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        if self._jogger is not None:
            jogger, backend = self._jogger, self._backend

            async def close() -> None:
                await jogger.stop("the station stops")
                if backend is not None:
                    await backend.close()

            try:
                asyncio.run_coroutine_threadsafe(close(), loop).result(CLOSE_TIMEOUT)
            except Exception:  # noqa: BLE001 - the station is ending: say so, go on
                log.warning("studio: the jog's back end did not close within %.1f s", CLOSE_TIMEOUT)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(CLOSE_TIMEOUT)
        self._loop = self._thread = None

    # ------------------------------------------------------------------ jogging
    def request(self, body: dict[str, Any]) -> JogRequest:
        """The page's request, checked against the open application's robot and cell (ValueError, one line)."""
        if self.app is None or self._jogger is None:
            raise ValueError("jog: open the jog panel first (no back end for jogging yet)")
        cell = self.app.cell
        return parse_request(body, self.app.robot, cell.frames if cell is not None else ())

    async def start(self, request: JogRequest, owner: object) -> tuple[bool, str]:
        if self._jogger is None:
            return False, "jog: open the jog panel first (no back end for jogging yet)"
        if self.safety:
            return False, "jog: the safety stop is raised: clear it before jogging"
        jogger = self._jogger

        async def start() -> tuple[bool, str]:
            ok, answer = await jogger.start(request)  # a jog going on is stopped first, under its own owner
            if ok:
                self.owner = owner
            self._noted(owner, "jog start", ok, answer, asdict(request))  # before the new jog can stop: in order
            return ok, answer

        return await self._on_loop(start)

    def beat(self, owner: object) -> None:
        if self._jogger is not None and self._loop is not None and owner is self.owner:
            self._loop.call_soon_threadsafe(self._jogger.beat)

    async def stop(self, reason: str, owner: object | None = None, refused: bool = False) -> None:
        """Stop the jog (only the owner's, when ``owner`` is given: a page closing stops its own jog)."""
        jogger = self._jogger
        if jogger is None or (owner is not None and owner is not self.owner):
            return
        await self._on_loop(lambda: jogger.stop(reason, refused))

    async def disconnect(self, owner: object, reason: str) -> None:
        """A page's jog connection closed: the jog it holds stops, then the close is audited -- on the jog's loop, so in
        that order and to the end even when the page's side is cancelled meanwhile (a server that ends the socket)."""
        jogger = self._jogger

        async def close() -> None:
            if jogger is not None and owner is self.owner:
                await jogger.stop(reason, True)
            self._noted(owner, "jog close", True, "the page's jog connection closed", {})

        future: Future[None] = asyncio.run_coroutine_threadsafe(close(), self._start_loop())
        await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(future)), ANSWER_TIMEOUT)  # a cancel here leaves it going

    async def safety_stop(self, active: bool) -> str:
        """Latch or clear the station's safety stop; raised, it stops any jog at once."""
        self.safety = active
        if active:
            await self.stop("jog stopped: the safety stop was raised", refused=True)
            return "jogging stopped and refused until the safety stop is cleared"
        return "jogging allowed again"

    async def tcp(self, group: str, app: Application) -> Pose | None:
        """The group's TCP in the world now, by the back end's word, for ``app``; ValueError while it jogs, or when
        the jog was made for another robot or cell (a teach must not take one robot's pose into another's cell)."""
        jogger, backend, target = self._jogger, self._backend, self._target
        if jogger is None or backend is None or target is None:
            raise ValueError("teach: open the jog panel first: the pose taught is where the jog's back end says the TCP is")
        if (target.robot, target.cell) != (app.robot.name, str(app.cell.path if app.cell is not None else "")):
            raise ValueError(f"teach: the jog panel was opened on another robot or cell ({target.robot}); reconnect it to this application first")
        if jogger.moving:
            raise ValueError("teach: the arm is jogging: release the button first")
        return await self._on_loop(lambda: _async(backend.tcp_pose, group))

    # ------------------------------------------------------------------ the loop
    def _start_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is not None:
            return self._loop
        ready = threading.Event()

        def main() -> None:
            loop = asyncio.new_event_loop()
            asyncio.set_event_loop(loop)
            self._clock = real_clock()
            self._clock.bind(loop)
            self._loop = loop
            ready.set()
            try:
                loop.run_forever()
            finally:
                loop.close()

        self._thread = threading.Thread(target=main, name="studio jog", daemon=True)
        self._thread.start()
        ready.wait(5.0)
        assert self._loop is not None
        return self._loop

    async def _on_loop(self, make: Callable[[], Coroutine[Any, Any, T]]) -> T:
        loop = self._start_loop()
        future: Future[T] = asyncio.run_coroutine_threadsafe(make(), loop)
        return await asyncio.wait_for(asyncio.wrap_future(future), ANSWER_TIMEOUT)

    def _noted(self, owner: object | None, what: str, ok: bool, answer: str, details: dict[str, Any]) -> None:
        if self.note is not None:
            try:
                self.note(owner, what, ok, answer, details)
            except Exception:  # noqa: BLE001 - the jog goes on (a stop must never wait for a log); said
                log.exception("studio: the jog's audit failed")

    def _tell(self, state: JogState) -> None:
        """From the jog's loop: every page hears of the change on its socket's loop; a stop is audited."""
        if self._moving and not state.moving:
            self._noted(self.owner, "jog stop", True, state.reason, {
                **(state.request or {}), "cause": stop_cause(state.reason), "by_check": state.refused,
                "stopped_in": None if state.stop_asked is None or state.stopped_at is None else round(state.stopped_at - state.stop_asked, 4),
                "travel_after_stop": state.travel_after_stop})
        self._moving = state.moving
        shown = state.to_json()
        for loop, listener in list(self.listeners):
            if not loop.is_closed():
                loop.call_soon_threadsafe(listener, shown)


async def _async(function: Callable[..., T], *args: Any) -> T:
    return function(*args)
