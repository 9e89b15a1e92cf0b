"""What validates, runs: every message a run will send fits the transport's size limit.

A run sends the cell model once (the ``CellSnapshot``, latched) and one ``SmRequest`` per call;
a receiver refuses any message over :data:`codec.MAX_MESSAGE_BYTES`.  A cell of 31,000 frames
used to pass ``validate`` and then be refused by every group machine, so the run waited for a
cell that never came.  The same limit, imported from the codec and never copied, is checked here.

The snapshot is sized piece by piece -- each frame, element and pose encoded on its own, the JSON
punctuation added -- and the count stops at the limit: a 200,000-frame cell costs the encoding of
the frames that fit, not of all of them.  Requests are bounded from above first (every character
of every text escaped at its widest, params at their longest): with the catalog's params that
bound is far below the limit and no request is encoded; otherwise each call is bounded, and
encoded only when its own bound is over the limit.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

from core_functions import limits
from core_functions.catalog import MAX_PARAM_LENGTH
from core_functions.limits import MAX_RETRIES
from core_functions.robots import RobotModel
from execution_engine.app_model.cell_model import Cell
from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, Location
from execution_engine.app_model.frame_tree import WORLD
from node_transport import codec
from node_transport.wire import CellSnapshot, SmRequest

#: JSON of one character at its widest: a character outside the BMP escaped as two \uXXXX.
_WIDEST_CHAR = 12
#: A request id the engine could send (engine-<session>-<group>-<counter>, counter of 13 digits).
_ID = "engine-ffffff-{group}-9999999999999"
#: The longest kind of synchronisation a barrier key names.
_SYNC = "master_slave"


def _size(value: Any) -> int:
    """Bytes of ``value`` as the codec writes it (UTF-8)."""
    return len(codec.encode(value).encode("utf-8"))


def snapshot_size(cell: Cell, limit: int = codec.MAX_MESSAGE_BYTES) -> int:
    """Bytes of ``codec.encode(cell.to_snapshot())``, exact up to ``limit``; past it, a number
    over ``limit`` (the count stops there).  A cell not bound to a robot has its joint poses left
    out (they are named by the robot's joints): the size is then a lower bound."""
    size = _size(CellSnapshot(name=cell.name))  # the frame of the message, with empty collections
    parts = cell.snapshot_parts()
    size += _sequence_size(parts["frames"], limit - size)
    for key in ("elements", "joint_poses", "truth", "joint_pose_groups"):
        if size > limit or (key == "joint_poses" and cell.robot is None):
            continue
        size += _mapping_size(parts[key], limit - size)
    return size


def _sequence_size(items: Iterator[Any], budget: int) -> int:
    """Bytes the items add inside ``[]``: each one plus a comma between two."""
    added = -1
    for item in items:
        added += _size(item) + 1
        if added > budget:
            break
    return max(added, 0)


def _mapping_size(pairs: Iterator[tuple[str, Any]], budget: int) -> int:
    """Bytes the pairs add inside ``{}``: ``"key":value`` each, a comma between two."""
    added = -1
    for key, value in pairs:
        added += _size(key) + 1 + _size(value) + 1
        if added > budget:
            break
    return max(added, 0)


def check_cell(cell: Cell, where: Location, display: str, log: DiagnosticLog) -> None:
    """The cell can run: its snapshot fits in a message (an error at ``where``: the application's
    ``cell=``, or the cell's root), and then every frame lies within the length bound in the world.

    The world check composes every frame; it runs on a cell that fits in a message, which bounds
    it to some 30,000 frames."""
    if check_snapshot(cell, where, display, log):
        check_world(cell, log)


def check_world(cell: Cell, log: DiagnosticLog) -> None:
    """Offsets add up down a chain: each frame's world position within core_functions.limits.LENGTH.

    Reported at the first frame of a chain that leaves the bound, not at every frame below it."""
    bound = limits.BY_UNIT["m"]
    for frame in cell.frames.values():
        position = cell.pose(frame.name).position
        if all(bound.contains(v) for v in position):
            continue
        if frame.parent != WORLD and not all(bound.contains(v) for v in cell.pose(frame.parent).position):
            continue
        where = frame.location or Location(str(cell.path or cell.name), 1, 1)
        shown = ", ".join(f"{v:g}" for v in position)
        log.append(Diagnostic.at(where, (
            f"frame {frame.name!r} is at ({shown}) m in the world, outside {bound.describe()}, {bound.what} "
            f"(its xyz adds to those of the frames above it)"
        )))


def check_snapshot(cell: Cell, where: Location, display: str, log: DiagnosticLog) -> bool:
    """An error at ``where`` when the snapshot cannot be sent; whether it can."""
    limit = codec.MAX_MESSAGE_BYTES
    size = snapshot_size(cell, limit)
    if size <= limit:
        return True
    log.append(Diagnostic.at(where, (
        f"cell file {display} is too large to run: its model with {len(cell.frames):,} frames, "
        f"{len(cell.elements):,} elements and {len(cell.joint_poses):,} joint poses is over {limit:,} bytes as a message "
        f"(the transport's limit, node_transport.codec.MAX_MESSAGE_BYTES), and every group machine "
        f"would refuse it; split the cell or leave out what this application does not use"
    )))
    return False


def request_size_bound(fixed: int, chars: int, texts: int) -> int:
    """An upper bound of a request's bytes: ``fixed`` (the rest of the message, measured) plus
    ``chars`` characters of text, each at its widest, in ``texts`` quoted strings."""
    return fixed + _WIDEST_CHAR * chars + 3 * texts


def check_requests(
    calls: Callable[[], Iterable[tuple[str, str, str, Sequence[str], int]]], longest: tuple[int, int, int],
    robot: RobotModel, app_name: str, cell_name: str, retries: int, log: DiagnosticLog, locate: Callable[[int], Location],
) -> None:
    """An error at each call whose request would be over the limit.

    ``calls()`` gives (operation id, group, function, params, offset of the call); ``longest`` is
    (the longest operation id, the longest function name, the most params of a function), so that
    when even a request of those at their widest fits -- the rule, with params of at most
    catalog.MAX_PARAM_LENGTH characters -- no call needs a look.  ``locate`` turns an offset into
    a location.  A request is built as the engine builds it
    (execution_engine.engine.Engine._requests), with the longest id, attempt number, barrier key
    and partner list the run could give it.
    """
    limit = codec.MAX_MESSAGE_BYTES
    attempt = min(retries, MAX_RETRIES) + 1
    partners = tuple(robot.group_names)
    widest_group = "x" * max(map(len, partners))
    fixed = _size(SmRequest(id=_ID.format(group=widest_group), function="f", attempt=attempt, sync=f"::{_SYNC}:{attempt}", partners=partners))
    shared = 2 * len(app_name) + len(cell_name)  # the name is also in the barrier key
    operation_chars, function_chars, most_params = longest
    worst = request_size_bound(fixed, 2 * operation_chars + function_chars + shared + most_params * MAX_PARAM_LENGTH, 6 + most_params)
    if worst <= limit:
        return  # the rule: no request can come near the limit
    for operation, group, function, params, at in calls():
        chars = 2 * len(operation) + len(function) + shared + sum(map(len, params))
        if request_size_bound(fixed, chars, 6 + len(params)) <= limit:
            continue  # far below: nothing to encode
        request = SmRequest(
            id=_ID.format(group=group), operation=operation, function=function, params=tuple(params), attempt=attempt,
            sync=f"{app_name}:{operation}:{_SYNC}:{attempt}", partners=partners, cell=cell_name,
        )
        size = _size(request)
        if size > limit:
            log.append(Diagnostic.at(locate(at), (
                f"the request for {function} on {group} in operation {operation} would be {size:,} bytes, over the "
                f"transport's limit of {limit:,} (node_transport.codec.MAX_MESSAGE_BYTES); shorten its params"
            )))
