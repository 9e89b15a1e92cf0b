"""Taking the robot to the safe pose after an error: retreat, slow down, move -- and say how it went.

An arm stopped by an error may be inside the work: a gripper in a tray slot, a rivet half in its
hole.  A joint move straight to the safe pose from there drags the tool sideways through the
part, and at the skill's process speed (10 % in the rivet skills) it also takes twenty seconds.
So the engine goes to the safe pose in three stages, each for every group at once:

1. **retreat** -- each arm that was stopped in the middle of a function backs its tool out along
   the tool axis (``error_policy retreat``, 0.05 m by default; a TCP's z points out of the hand,
   into the work, so the retreat is a linear ``move_relative`` of -retreat along the tool's z).
   Skipped for an arm that was not working (its function had finished, it sat the operation out
   or only waited: its skill already left the work), for ``torso_head`` (no tool) and when
   ``retreat="0"``.  A retreat the robot cannot make here (unreachable, a joint limit, not
   supported by the robot) is skipped and the arm still goes to the safe pose: the retreat is
   a precaution, and an arm at the edge of its workspace is not inside a part.  Any other failed
   retreat (a collision, a controller fault, a stop) leaves that arm where it is: moving it
   further could make things worse, and the report says so.
2. **speed** -- every group that moves sets ``error_policy safe_speed`` (0.3 of its maximum by
   default), so the move is neither the skill's crawl nor full speed.  A group whose speed could
   not be set still moves, at the speed it had.
3. **move** -- ``move_to_joint_pose(safe_pose)`` for every group the pose covers.

Each step of each group becomes a :class:`SafePoseStep` of the report, with its outcome.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol

from core_functions.catalog import BindContext, Catalog
from execution_engine.app_model.model import Application, Call
from execution_engine.engine.report import SafePoseStep
from node_transport.wire import FaultKind, SmResult

#: Retreat faults that mean "not possible from here", after which the arm still moves.
RETREAT_IMPOSSIBLE = (FaultKind.UNREACHABLE, FaultKind.JOINT_LIMIT, FaultKind.UNSUPPORTED)


class StageRunner(Protocol):
    """What the engine lends the safe-pose sequence: run one stage, bring machines back to Ready."""

    async def run_stage(self, stage: str, calls: dict[str, Call]) -> dict[str, SmResult | None]:
        """Send every call at once; each group's result, or None when none came in time."""

    async def make_ready(self, groups: Iterable[str]) -> list[str]:
        """Reset the machines in ErrorHandling; the groups that did not get back to Ready."""


@dataclass(frozen=True)
class SafePosePlan:
    """Who moves to the safe pose, who retreats first, and how."""

    pose: str
    speed: float
    retreat: float
    movers: tuple[str, ...]  # the groups the pose covers, in the robot's order
    in_work: frozenset[str]  # groups stopped in the middle of a function (not a wait)

    @staticmethod
    def build(app: Application, catalog: Catalog, in_work: Iterable[str]) -> SafePosePlan:
        policy = app.error_policy
        assert policy.safe_pose is not None
        spec = catalog.get("move_to_joint_pose")
        assert spec is not None
        movers = tuple(
            g for g in app.robot.group_names if not spec.check((policy.safe_pose,), BindContext(app.robot, g, app.cell))
        )
        return SafePosePlan(policy.safe_pose, policy.safe_speed, policy.retreat, movers, frozenset(in_work))

    def retreats(self, app: Application) -> tuple[str, ...]:
        arms = [g for g in self.movers if app.robot.group(g).kind == "arm"]
        return tuple(g for g in arms if g in self.in_work) if self.retreat > 0 else ()


def _failure(result: SmResult | None) -> str:
    return "no result in time" if result is None else (result.error or result.outcome)


async def go_safe(runner: StageRunner, app: Application, plan: SafePosePlan) -> list[SafePoseStep]:
    """Run the three stages; every step of every group is reported, failed ones included."""
    steps: list[SafePoseStep] = []
    movers = await _ready(runner, list(plan.movers), steps, "error")
    retreating = tuple(g for g in plan.retreats(app) if g in movers)
    for group in movers:
        if app.robot.group(group).kind == "arm" and group not in retreating:
            why = "retreat=0" if plan.retreat <= 0 else "it was not working in the cell when the error came"
            steps.append(SafePoseStep(group, "retreat", "skipped", why))
    distance = f"{-plan.retreat!r}"
    retreat = {g: Call(g, "move_relative", ("0", "0", distance, "0", "0", "0", "tool")) for g in retreating}
    for group, result in (await runner.run_stage("retreat", retreat)).items():
        if result is not None and result.outcome == "succeeded":
            steps.append(SafePoseStep(group, "retreat", "done", f"{plan.retreat:g} m back along the tool axis"))
        elif result is not None and result.fault in RETREAT_IMPOSSIBLE:
            steps.append(SafePoseStep(group, "retreat", "skipped", f"not possible here: {_failure(result)}"))
        else:
            steps.append(SafePoseStep(group, "retreat", "failed", f"{_failure(result)}; the arm stays where it is"))
            movers.remove(group)
    movers = await _ready(runner, movers, steps, "retreat")
    speed = {g: Call(g, "set_speed", (f"{plan.speed!r}",)) for g in movers}
    for group, result in (await runner.run_stage("speed", speed)).items():
        if result is not None and result.outcome == "succeeded":
            steps.append(SafePoseStep(group, "speed", "done", f"{plan.speed:.0%} of maximum"))
        else:
            steps.append(SafePoseStep(group, "speed", "failed", f"{_failure(result)}; moving at the speed it had"))
    movers = await _ready(runner, movers, steps, "speed")
    move = {g: Call(g, "move_to_joint_pose", (plan.pose,)) for g in movers}
    for group, result in (await runner.run_stage("move", move)).items():
        if result is not None and result.outcome == "succeeded":
            steps.append(SafePoseStep(group, "move", "done", f"at {plan.pose!r}"))
        else:
            steps.append(SafePoseStep(group, "move", "failed", _failure(result)))
    return steps


async def _ready(runner: StageRunner, movers: list[str], steps: list[SafePoseStep], after: str) -> list[str]:
    """Groups still able to go on: a failed step leaves a machine in ErrorHandling until reset."""
    stuck = await runner.make_ready(movers)
    for group in stuck:
        steps.append(SafePoseStep(group, "move", "failed", f"its machine did not return to Ready after the {after}"))
    return [g for g in movers if g not in stuck]
