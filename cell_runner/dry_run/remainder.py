"""The dry run of a paused run's edited remainder, from where the run stands (the engine's ``RemainderCheck``).

An edit of a paused run (:mod:`execution_engine.engine.remainder_swap`) is swapped in only when its
remainder -- the operations not started yet -- passes the same dry run every start passes, started
from the run's present state, not from the application's start:

* the joints where the robot really is (measured from the back end, as :mod:`.start` does);
* the frames vision located so far: the remainder's motions go where the run's will, to the measured
  poses (a located frame's pose in the checked cell is its measured one, its children move with it);
* the flags set so far (set first, by the engine's own ``set_flag``, which moves nothing);
* with ``sync="flags"``, each group from its own position (the calls it has ended left out, the one it is
  in run again from where the arm is) and the zones held as they are (the holder's call first);
* the outcomes of the tested functions that ran: an operation whose ``<if>`` on them is not met is
  left out as the run will leave it out; one whose ``<if>`` is met runs without that condition.

The findings come back as diagnostics at the new application's lines (the remainder keeps its
operations' lines), so the page places them at the cells of the builder.
"""
from __future__ import annotations

import asyncio
from collections.abc import Mapping, Sequence
from dataclasses import replace

from cell_runner.dry_run.placement import PlacementError
from cell_runner.dry_run.runner import DryRunError, dry_run_setup
from cell_runner.dry_run.simulators import DryRunSetup
from cell_runner.dry_run.start import Measure, StartRefused
from core_functions.geometry import Pose
from execution_engine.app_model.cell_model import Cell
from execution_engine.app_model.diagnostics import Diagnostic
from execution_engine.app_model.model import WAIT, Application, Call, Condition, Operation
from execution_engine.engine.flags import SET_FLAG
from execution_engine.engine.remainder_swap import PresentState, RemainderCheck
from node_transport.clock import Clock


def remainder_app(new: Application, state: PresentState) -> Application:
    """What is left to run of ``new`` from ``state``: its operations from the frontier (branches on outcomes
    already known resolved), in the cell as vision found it, after the flags set so far; with ``sync="flags"``
    each group's calls from where it stands (:func:`flags_remainder`)."""
    cell = located_cell(new.cell, state.located) if new.cell is not None else None
    if state.groups:
        return replace(new, operations=flags_remainder(new, state), cell=cell)
    done = {op.id for op in new.operations[: state.frontier]}
    operations: list[Operation] = list(_flag_prelude(new, state.flags))
    for operation in new.operations[state.frontier:]:
        known = [c for c in operation.when if c.operation in done]
        if not all(c.met(state.outcomes.get(f"{c.operation}/{c.group}")) for c in known):
            continue  # its branch was decided the other way before the pause
        operations.append(replace(operation, when=tuple(c for c in operation.when if c.operation not in done)))
    return replace(new, operations=tuple(operations), cell=cell)


def flags_remainder(new: Application, state: PresentState) -> tuple[Operation, ...]:
    """sync="flags": each group starts from its own position -- its calls that ended (or were left out) are left out
    here too, the call it is in runs again from where the arm is (the rest of its motion, its wait for a flag), the
    rest as they are.  The flags set stay set (set first); a zone held stays held: the call inside it goes first,
    ahead of every other call of that zone (its operation split, the holder's call in front); an ``<if>`` whose tested
    function has ended (or was left out) is resolved as the run resolves it."""
    groups = new.robot.group_names

    def decided(condition: Condition) -> bool:
        at = state.groups.get(condition.group)
        return f"{condition.operation}/{condition.group}" in state.outcomes or (at is not None and condition.operation in at.done)

    holders = {call for call in state.zones.values()}
    front: list[Operation] = []
    rest: list[Operation] = []
    for operation in new.operations:
        known = [c for c in operation.when if decided(c)]
        if not all(c.met(state.outcomes.get(f"{c.operation}/{c.group}")) for c in known):
            continue  # its branch was decided the other way before the pause
        when = tuple(c for c in operation.when if not decided(c))
        calls = dict(operation.calls)
        for group, call in operation.calls.items():
            at = state.groups.get(group)
            if at is not None and operation.id in at.done:
                calls[group] = _sits_out(call)
            elif (operation.id, group) in holders and not call.implicit:
                front.append(replace(operation, when=when, calls={g: call if g == group else _sits_out(c) for g, c in operation.calls.items()}))
                calls[group] = _sits_out(call)
        if any(not c.implicit for c in calls.values()):
            rest.append(replace(operation, when=when, calls={g: calls[g] for g in groups if g in calls}))
    return (*_flag_prelude(new, state.flags), *front, *rest)


def _sits_out(call: Call) -> Call:
    """``call`` as a group left out of its operation (the implicit wait), where it is written."""
    return Call(call.group, WAIT, (), implicit=True, file=call.file, line=call.line, col=call.col)


def _flag_prelude(app: Application, flags: Sequence[str]) -> list[Operation]:
    """One operation per flag set so far, its first group setting it (the others wait): no motion."""
    groups = app.robot.group_names
    out = []
    for k, flag in enumerate(flags):
        calls = {g: Call(g, SET_FLAG, (flag,)) if g == groups[0] else Call(g, "wait", ("0",), implicit=True) for g in groups}
        out.append(Operation(id=f"present_flag_{k + 1}", name=f"flag {flag} set before the pause", line=0, col=0, calls=calls))
    return out


def located_cell(cell: Cell, located: Mapping[str, Pose]) -> Cell:
    """``cell`` with each located frame at its measured world pose (in its parent's frame); its true pose, if the
    cell gives one for simulated vision, stays where it was."""
    known = {name: pose for name, pose in located.items() if name in cell.frames}
    if not known:
        return cell
    truth = cell.to_snapshot().truth
    frames = dict(cell.frames)
    for name, world in known.items():
        frame = frames[name]
        parent = cell.pose(frame.parent) if frame.parent in cell.frames else Pose()
        true = truth.get(name)
        frames[name] = replace(frame, local=parent.inverse().compose(world), actual=world.inverse().compose(true) if true is not None else None)
    return replace(cell, frames=frames)


def remainder_check(setup: DryRunSetup, trajectory_db: str | None, measure: Measure, clock: Clock) -> RemainderCheck:
    """The check the engine calls on an edit: the dry run of the remainder from the joints measured now."""

    async def check(new: Application, state: PresentState) -> Sequence[Diagnostic]:
        try:
            joints = (await measure()).joints
        except StartRefused as refusal:
            return [Diagnostic(str(new.path), 1, 1, f"cannot check the edit from where the robot is: {refusal.reason}")]
        target = remainder_app(new, state)

        def dry() -> list[Diagnostic]:
            try:
                report = dry_run_setup(target, setup, trajectory_db, joints)
            except (PlacementError, DryRunError, ValueError, KeyError) as error:
                return [Diagnostic(str(new.path), 1, 1, f"the dry run of the edit broke down: {error}")]
            notes = [Diagnostic(str(new.path), 1, 1, f"not checked: {note}") for note in report.notes] if not report.ok else []
            return [*report.diagnostics(), *notes]

        with clock.held():  # a simulated clock stands still while the simulator works
            return await asyncio.to_thread(dry)

    return check
