"""``execution_engine/run_application``: the RunApplication action, so any ROS 2 client runs applications.

::

    ros2 action send_goal /execution_engine/run_application dual_arm_executive_interfaces/action/RunApplication \\
        "{application_file: /path/rivet_installation.xml}" --feedback

The goal names an application file, or carries the XML text (its cell file is then looked for in the
working directory of the engine).  A goal is refused while a run is in progress.  The application is
validated first: one with errors ends the goal aborted, its diagnostics in ``report``.  Feedback is
the engine's status as it changes (operation, index, count, each group's state and function);
the result is the outcome (``finished``, ``failed``, ``stopped``, ``invalid``, ``refused``), ``ok``
and the run's report.  How the application is run is the owner's (``runner``): the engine
process's checks it from where the robot is first (cell_runner/dry_run/cell_start.py), so a
goal whose run would collide, or after a cancelled one would start from mid-application, is
refused with the dry run's findings as its report, or starts with a way back the dry run proved
safe.  A cancel is the operator's stop: every group's motion stopped, then Finish, and the goal
ends cancelled with the report of what was done; a cancel while the run is being checked ends it
before anything moves.  ``backend`` must be empty or the back end
the cell runs (the application robot's); ``speed`` is the bridge's own parameter (``--speed`` of the
launch, ``-p speed:=F``), so a goal may only leave it 0.
"""
from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from execution_engine.app_model import Application, read_application
from execution_engine.engine.engine import ExecutionEngine
from node_transport import codec, mirrors, typed
from node_transport.action import ActionServer, GoalHandle
from node_transport.port import Node
from node_transport.qos import EVENTS
from node_transport.wire import ENGINE_STATUS, EngineStatus

ACTION_NAME = "execution_engine/run_application"
_PACKAGE = "dual_arm_executive_interfaces"
_BUSY = ("running", "paused", "stepping", "error", "alarm", "stopping")


RunApplication = mirrors.action(f"{_PACKAGE}/action/RunApplication")
RunApplicationGoal, RunApplicationResult, RunApplicationFeedback = RunApplication.Goal, RunApplication.Result, RunApplication.Feedback
SendGoal, GetResult = RunApplication.SendGoal, RunApplication.GetResult
GroupProgressMsg = typed.GroupProgressMsg


def feedback_of(status: EngineStatus) -> Any:
    return RunApplicationFeedback(
        operation=status.operation_id or "",
        operation_index=max(0, status.operation_index),
        operation_count=max(0, status.operation_count),
        groups=tuple(GroupProgressMsg(g, p.state, p.operation or "", p.function or "") for g, p in sorted(status.groups.items())),
    )


@dataclass(frozen=True)
class GoalOutcome:
    """How a goal's run ended: the result's outcome, ok and report."""

    outcome: str
    ok: bool
    report: str


#: Runs a goal's (valid) application on the engine and says how it ended.
GoalRunner = Callable[[Application], Awaitable[GoalOutcome]]


class RunApplicationServer:
    """Runs goals on ``engine`` (one at a time) and reports them back.

    ``runner`` runs a goal's application; without one the application is run as it is, unchecked
    (the engine parameter ``check:=false``)."""

    def __init__(self, node: Node, engine: ExecutionEngine, runner: GoalRunner | None = None) -> None:
        self.node = node
        self.engine = engine
        self.runner = runner or self._run_unchecked
        self.catalog = engine.catalog  # goals are read against the engine's library
        self.current: GoalHandle | None = None
        self.busy = False  # a goal was accepted and has not ended
        self.server = ActionServer(node, RunApplication, ACTION_NAME, execute=self._execute, accept=self._accept, cancel=self._cancel)
        self._stops: set[asyncio.Task[object]] = set()
        node.create_subscription(typed.EngineStatusMsg, ENGINE_STATUS, self._on_status, EVENTS)

    def _accept(self, goal: Any) -> str | None:
        if self.busy or self.engine.state in _BUSY:
            return f"a run is in progress (engine {self.engine.state})"
        if not goal.application_file and not goal.application_xml:
            return "the goal names no application (application_file or application_xml)"
        self.busy = True  # from the answer on: a second goal is refused even before this one executes
        return None

    def _cancel(self, handle: GoalHandle) -> None:
        task = asyncio.get_running_loop().create_task(self.engine.operator_command("stop", f"action {self.server.name} cancel"))
        self._stops.add(task)
        task.add_done_callback(self._stops.discard)

    def _on_status(self, msg: Any) -> None:
        if self.current is None:
            return
        try:
            status = typed.from_msg(EngineStatus, msg, self.node.clock, source=self.node.resolve(ENGINE_STATUS))
        except codec.WireError as error:
            self.node.logger.warning("%s: %s", self.node.fully_qualified_name, error)
            return
        self.server.publish_feedback(self.current, feedback_of(status))

    def _load(self, goal: Any) -> tuple[Application | None, str]:
        if goal.application_file:
            app, diagnostics = read_application(Path(goal.application_file), self.catalog)
        else:
            app, diagnostics = read_application(Path.cwd() / "goal.xml", self.catalog, data=goal.application_xml.encode("utf-8"))
        text = "\n".join(str(d) for d in diagnostics if d.is_error)
        if app is not None and goal.backend and goal.backend != app.robot.default_backend:
            return None, f"this cell runs the {app.robot.default_backend} back end, not {goal.backend}"
        if app is not None and goal.speed != 0.0:
            return None, "speed is the bridge's parameter (launch --speed, -p speed:=F); leave it 0 in the goal"
        return app, text

    async def _execute(self, handle: GoalHandle) -> Any:
        try:
            app, problems = self._load(handle.goal)
            if app is None:
                handle.aborted = True
                return RunApplicationResult("invalid", False, problems)
            if handle.cancel_requested:
                return RunApplicationResult("stopped", False, f"{app.name}: cancelled before it started")
            self.current = handle
            done = await self.runner(app)
        finally:
            self.current = None
            self.busy = False
        handle.aborted = not done.ok
        return RunApplicationResult(done.outcome, done.ok, done.report)

    async def _run_unchecked(self, app: Application) -> GoalOutcome:
        report = await self.engine.run(app)
        return GoalOutcome(report.outcome, report.ok, "\n".join(report.summary_lines()))
