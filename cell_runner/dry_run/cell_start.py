"""The start check on a graph: an engine node measures the robot on ``joint_states`` and runs checked.

``launch``, ``ros2 launch`` and every RunApplication goal start a run in an engine node that
does not hold the back end: the robot is measured from the bridge's ``joint_states`` -- a sample
taken after the run was asked for, every joint of the robot in it -- and the run is planned and
carried out as :mod:`.start` says (the dry run uses the simulator of the back end the cell's bridge
drives, with its options, as ``run --robot B --backend-option ...`` does -- ``launch`` gives the engine
them as ``check_backend`` and ``check_options`` (:mod:`cell_runner.engine_check`); a hand-started engine
without them checks on the application robot's default back end with its default options; a cell of
several robots on each robot's own back end and options, from the cell -- and the machines' trajectory
database).  A refusal leaves the
robot where it is: a goal ends aborted with outcome ``refused`` and the findings as its report;
the engine process started with an application prints them and ends with exit code 1.

As ``run``, the node first looks for the kept verdict of the application's dry run from the
simulator's start (:mod:`.verdict_cache`, the same key as the command line's), else does that dry
run and keeps its passed verdict: an unchanged application is not dry-run again by the next goal,
the next launch or the command line, and the node's console says so.
"""
from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from cell_runner.dry_run.check import keeping_for
from cell_runner.dry_run.placement import PlacementError
from cell_runner.dry_run.report import DryRunReport
from cell_runner.dry_run.runner import DryRunError, dry_run_setup
from cell_runner.dry_run.simulators import DryRunSetup, setup_for
from cell_runner.dry_run.start import MeasuredState, StartRefused, UntrustedState, check_run, measured
from core_functions.cell_robots import CellRobotModel
from execution_engine.app_model.model import Application
from execution_engine.engine.engine import ExecutionEngine
from execution_engine.engine.report import RunReport
from execution_engine.engine.run_action import GoalOutcome
from node_transport.msgs import JointState
from node_transport.port import Node
from node_transport.qos import SENSOR
from node_transport.wire import JOINT_STATES
from robot_bridges.backend import BackendOptions
from robot_bridges.registry import check_options


class CellStarts:
    """Checked starts for the engine on ``node``: the measured joints, the plan, the run."""

    def __init__(
        self, node: Node, engine: ExecutionEngine, trajectory_db: str, timeout: float, backend: str = "", options: dict[str, str] | None = None,
    ) -> None:
        self.node = node
        self.engine = engine
        self.trajectory_db = trajectory_db or None
        self.timeout = timeout
        self.backend = backend  # '' : each application robot's default back end
        self.options = dict(options or {})  # checked as launch checks --backend-option (the same back end's parse_options)
        if backend or self.options:
            given = "; ".join(f"{k}={v}" for k, v in self.options.items()) or "its default options"
            node.logger.info("%s: each run is checked on the dry run of the %s back end (%s)", node.fully_qualified_name, backend or "robot's default", given)
        self.topic = node.resolve(JOINT_STATES)
        self._latest: dict[str, tuple[float, int]] = {}  # joint -> (position, sample number)
        self._samples = 0
        self._arrived = asyncio.Event()
        # best effort: takes a reliable publisher (the bridges) as well as a best-effort one
        node.create_subscription(JointState, JOINT_STATES, self._on_joints, SENSOR)

    def _on_joints(self, msg: JointState) -> None:
        self._samples += 1
        for name, position in zip(msg.name, msg.position):
            self._latest[name] = (float(position), self._samples)
        self._arrived.set()

    def measure_for(self, app: Application) -> Callable[[], Any]:
        async def measure() -> MeasuredState:
            return await self.measure(app)

        return measure

    async def measure(self, app: Application) -> MeasuredState:
        """Every joint of the robot from samples that arrived after this call (bounded by ``timeout``)."""
        after = self._samples
        names = app.robot.joint_names
        clock = self.node.clock
        deadline = clock.now() + self.timeout
        while not all(self._latest.get(n, (0.0, 0))[1] > after for n in names):
            remaining = deadline - clock.now()
            if remaining <= 0:
                stale = [n for n in names if self._latest.get(n, (0.0, 0))[1] <= after]
                raise StartRefused(
                    f"no joint positions on {self.topic} for {', '.join(stale[:3])}{' ...' if len(stale) > 3 else ''} within {self.timeout:g} s: "
                    "the run is checked from where the robot is, and the bridge does not say (is it running?)"
                )
            self._arrived.clear()
            try:
                await clock.wait_for(self._arrived.wait(), remaining)
            except asyncio.TimeoutError:
                continue
        try:
            return measured(app.robot, names, tuple(self._latest[n][0] for n in names), f"{self.topic}")
        except UntrustedState as error:
            raise StartRefused(str(error)) from None

    async def run(self, app: Application, say: Callable[[str], None]) -> RunReport:
        """Run ``app`` checked from the measured joints; StartRefused when it must not start."""
        setup = self.setup(app)
        checked = await self.verdict(app, setup, say)
        run = await check_run(self.engine, app, setup, self.trajectory_db, self.measure_for(app), self.node.clock, checked=checked, say=say)
        return await run.run()

    def setup(self, app: Application) -> DryRunSetup:
        """The dry run of ``app`` on the back end the bridge drives (``run``'s setup_for with the same options);
        StartRefused when that back end cannot drive ``app``'s robot or refuses an option."""
        if not self.backend and not self.options:
            return setup_for(app.robot.default_backend, BackendOptions(robot=app.robot))
        if isinstance(app.robot, CellRobotModel):
            raise StartRefused(
                f"parameters check_backend/check_options: {app.name} runs a cell of several robots, checked on each robot's own back end "
                "and options from the cell; leave check_backend and check_options empty"
            )
        backend = self.backend or app.robot.default_backend
        options = BackendOptions(robot=app.robot, extra=self.options)
        try:
            check_options(backend, options, 1.0)
        except (ValueError, KeyError) as error:
            raise StartRefused(f"parameters check_backend/check_options: {error.args[0] if isinstance(error, KeyError) and error.args else error}") from None
        return setup_for(backend, options)

    async def verdict(self, app: Application, setup: DryRunSetup, say: Callable[[str], None]) -> DryRunReport | None:
        """The dry run from the simulator's start, as ``run`` does first: the kept verdict (and a line saying
        so), else a dry run whose passed verdict is kept; None when none can be kept (the start check then
        dry-runs from the measured joints, as it always did).  The start check uses it only where the robot
        is measured to be at that start; elsewhere it plans the way back to it."""
        keeping = keeping_for(app, setup, self.trajectory_db)
        if keeping is None:
            return None
        kept = keeping.kept()
        if kept is not None:
            say(kept.line())
            return kept.report
        with self.node.clock.held():  # a simulated clock stands still while the dry run blocks a thread
            try:
                report = await asyncio.to_thread(dry_run_setup, app, setup, self.trajectory_db)
            except (DryRunError, PlacementError, KeyError, ValueError, OSError, ConnectionError) as error:
                self.node.logger.info("%s: the dry run from the simulator's start: %s", self.node.fully_qualified_name, error)
                return None  # the start check dry-runs again and refuses with its own words
        keeping.keep(report, [p for p in (app.path, app.cell.path if app.cell is not None else None, self.trajectory_db) if p])
        return report

    async def run_goal(self, app: Application) -> GoalOutcome:
        """A RunApplication goal's run: its outcome, ok and report (the findings when refused)."""
        lines: list[str] = []
        try:
            report = await self.run(app, lines.append)
        except StartRefused as refusal:
            return GoalOutcome("refused", False, "\n".join([*refusal.lines, f"{app.path}: not run: {refusal.reason}"]))
        return GoalOutcome(report.outcome, report.ok, "\n".join([*lines, *report.summary_lines()]))
