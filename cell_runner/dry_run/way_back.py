"""The ways back to where an application starts, for a robot left somewhere else (a cancelled run).

A way back is a small application of its own: each arm that is away backs its tool out along
the tool axis (the error policy's ``retreat``: it may be inside the work), every group that is
away slows to the policy's ``safe_speed``, goes to its joints at the application's start with a
joint move, and takes full speed again (what a fresh start has).  The candidates differ in what
moves at once -- everything together (quickest), then one group at a time in either order of
the arms, then the same without the retreat (which a robot at the edge of its workspace cannot
make) -- and :mod:`.start` runs them through the dry run until one is proved free of collisions.
Non-arm groups (a torso that swings both arms) go last in the one-at-a-time ways.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from cell_runner.dry_run.report import JointPositions
from execution_engine.app_model.model import WAIT, Application, Call, ErrorPolicy, Operation

#: A way back is run as its own application: nothing to retry (the same motion fails the same way)
#: and no safe pose to fall back to (it is the way to safety).
_POLICY = ErrorPolicy(retries=0, action="abort")
PREFIX = "way_back"


@dataclass(frozen=True)
class WayBack:
    """One candidate: the application that runs it and what it does, in words."""

    app: Application
    description: str


def away(app: Application, state: JointPositions, start: JointPositions, tolerance: float) -> tuple[str, ...]:
    """The groups with a joint farther than ``tolerance`` (rad) from the start, in the robot's order."""
    now, then = dict(zip(*state)), dict(zip(*start))
    return tuple(
        g.name for g in app.robot.groups if any(abs(now.get(j, 0.0) - then.get(j, 0.0)) > tolerance for j in g.joint_names)
    )


def candidates(app: Application, start: JointPositions, movers: tuple[str, ...]) -> list[WayBack]:
    """Every way back worth trying for ``movers``, the likeliest first (see the module)."""
    robot = app.robot
    arms = tuple(g for g in movers if robot.group(g).kind == "arm")
    others = tuple(g for g in movers if g not in arms)
    policy = app.error_policy
    retreats = (True, False) if arms and policy.retreat > 0 else (False,)
    orders = [None, (*arms, *others)]
    if len(arms) > 1:
        orders.append((*reversed(arms), *others))
    found: list[WayBack] = []
    seen: set[tuple[tuple[str, ...], ...]] = set()
    for retreat in retreats:
        for order in orders:
            steps = _steps(arms if retreat else (), movers, order)
            if steps in seen:  # one group: together and one at a time are the same way
                continue
            seen.add(steps)
            found.append(_way_back(app, start, steps, retreat, order))
    return found


def _steps(retreating: tuple[str, ...], movers: tuple[str, ...], order: tuple[str, ...] | None) -> tuple[tuple[str, ...], ...]:
    """Who moves in each stage: retreats, speed, moves, speed -- together, or one group per stage."""
    def staged(groups: tuple[str, ...]) -> tuple[tuple[str, ...], ...]:
        if not groups:
            return ()
        if order is None:
            return (groups,)
        return tuple((g,) for g in order if g in groups)

    return (*(("retreat", *s) for s in staged(retreating)), ("speed", *movers), *(("move", *s) for s in staged(movers)), ("restore", *movers))


def _way_back(app: Application, start: JointPositions, steps: tuple[tuple[str, ...], ...], retreat: bool, order: tuple[str, ...] | None) -> WayBack:
    policy = app.error_policy
    where = dict(zip(*start))
    operations = []
    for index, (stage, *groups) in enumerate(steps, start=1):
        calls = {}
        for group in app.robot.group_names:
            if group not in groups:
                calls[group] = Call(group, WAIT, ("0",), implicit=True)
            elif stage == "retreat":
                calls[group] = Call(group, "move_relative", ("0", "0", f"{-policy.retreat!r}", "0", "0", "0", "tool"))
            elif stage == "speed":
                calls[group] = Call(group, "set_speed", (f"{policy.safe_speed!r}",))
            elif stage == "restore":
                calls[group] = Call(group, "set_speed", ("1.0",))
            else:
                joints = " ".join(repr(float(where[j])) for j in app.robot.group(group).joint_names)
                calls[group] = Call(group, "move_joints", (joints,))
        operations.append(Operation(f"{PREFIX}_{index}", f"way back: {stage} {', '.join(groups)}", 0, 0, calls))
    way = replace(app, name=f"{app.name} (way back)", operations=tuple(operations), error_policy=_POLICY, sync="operation")
    arms = [g for g in _groups(steps, "retreat")]
    movers = _groups(steps, "move")
    how = "together" if order is None else f"one at a time ({', '.join(movers)})"
    words = []
    if retreat and arms:
        words.append(f"{', '.join(arms)} back {policy.retreat:g} m along the tool axis")
    words.append(f"{', '.join(sorted(set(movers), key=movers.index))} to the start at {policy.safe_speed:.0%} speed, {how}")
    return WayBack(way, "; then ".join(words))


def _groups(steps: tuple[tuple[str, ...], ...], stage: str) -> list[str]:
    return [g for s, *groups in steps if s == stage for g in groups]
