"""Putting a dry run's simulated robot where the real robot is, before the application starts.

A run is checked from where the robot really is (docs/application_xml.md, "Checking before
anything moves"), not from the pose a simulator starts in: after a cancelled run the arms may be
anywhere.  Every simulator takes the same way there, through the bridge port: one joint move
per group to the measured positions.  It is not part of the application -- it runs before the
dry run's time starts, the dry-run back end does not see it (no finding, no timeline, no
collision sweep: how the simulator got there does not matter), and nothing checks collisions
on the way (the dry run sweeps collisions itself, from the measured state on).
"""
from __future__ import annotations

from cell_runner.dry_run.report import JointPositions
from core_functions.primitives import MoveJoints
from core_functions.robots import RobotModel
from robot_bridges.backend import BridgeError, RobotBackend

#: How close (rad) the simulator must come to each measured joint: a simulator that talks in
#: degrees with few decimals (V+) lands within 1e-5 rad.
PLACEMENT_TOLERANCE = 1e-4


class PlacementError(Exception):
    """The simulator could not be put where the robot is (a defect or a simulator limit, said in one line)."""


async def place(backend: RobotBackend, robot: RobotModel, state: JointPositions) -> None:
    """Move ``backend``'s robot (a simulator) to ``state``; PlacementError naming the joint otherwise."""
    where = dict(zip(*state))
    missing = [name for name in robot.joint_names if name not in where]
    if missing:
        raise PlacementError(f"no measured position for {', '.join(missing)}")
    for group in robot.groups:
        names = group.joint_names
        try:
            await backend.execute(group.name, MoveJoints(tuple(float(where[n]) for n in names), names))
        except BridgeError as error:
            raise PlacementError(f"the {backend.name} simulator cannot put {group.name} where the robot is: {error}") from None
    now = dict(zip(*backend.joint_state()))
    off = [(n, abs(now.get(n, float("nan")) - where[n])) for n in robot.joint_names]
    bad = [(n, d) for n, d in off if not d <= PLACEMENT_TOLERANCE]
    if bad:
        name, distance = bad[0]
        raise PlacementError(f"the {backend.name} simulator stopped {distance:.3g} rad from the measured {name}")
