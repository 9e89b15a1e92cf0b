"""What ``run`` needs of the flight recorder: start/stop around a run (its options are the command line's).

Recording (``--record``), checkpoints (``--checkpoint``, by default next to the trace or the
recording) and resuming (``--resume``, ``--on-interrupted``) are set up here, so ``run`` only
calls :func:`prepare_flight` (before any file is written), :func:`start_recording` and
:func:`stop_recording`.  Below the options, everything reads the
run's :class:`~cell_runner.settings.RunSettings`.
"""
from __future__ import annotations

import sqlite3
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO

from app_functions.registry import full_catalog
from cell_runner.output_files import FilePlan, Output, WriteFailure, same_file, stores_data
from cell_runner.run_checks import app_inputs, run_files
from cell_runner.settings import Outputs, RunSettings
from core_functions.trajectory_store import application_store
from execution_engine.app_model import Application
from execution_engine.app_model.model import Operation
from execution_engine.checkpoint.resume import ResumePlan, app_meta, next_name, plan_resume
from execution_engine.checkpoint.store import ANSWERS, SKIPPED, CheckpointError, CheckpointStore
from execution_engine.checkpoint.writer import CheckpointWriter
from execution_engine.observers import RunObserver
from execution_engine.recorder.recorder import Recorder
from execution_engine.recorder.writer import McapSink
from node_transport.port import Node, Transport


def checkpoint_path(settings: RunSettings) -> str | None:
    """``--checkpoint``, else the resumed checkpoint, else next to the trace or the recording (a file, not a device)."""
    outputs = settings.outputs
    if outputs.checkpoint:
        return str(outputs.checkpoint)
    if settings.resume:
        return str(settings.resume)
    bases = [p for p in (outputs.trace, outputs.record) if p and stores_data(p)]
    if not bases:  # none, or devices (/dev/null): no folder to keep a checkpoint in
        return None
    base = bases[0]
    path = Path(base)  # (a directory given as --trace is refused by name, before this path is checked)
    return str(path.parent / (path.name.split(".")[0] + ".checkpoint.sqlite"))


def prepare_flight(app: Application, settings: RunSettings) -> RunSettings:
    """Before anything is written: check ``--resume`` (CheckpointError naming what is wrong), name
    the resumed run's trace and recording (never the files of the run it continues), the
    checkpoint and the trajectory database, then check every file the run reads and writes
    against each other (:func:`run_files`: Refused, one line, nothing written).  Returns the
    settings with every output named."""
    derived: dict[str, str] = {}
    resume = settings.resume
    outputs = settings.outputs
    if resume:
        outputs = _prepare_resume(app, outputs, str(resume), derived)
    given = outputs.checkpoint
    outputs = replace(outputs, checkpoint=checkpoint_path(replace(settings, outputs=outputs)))
    if outputs.checkpoint and not given and not resume:
        trace = outputs.trace
        derived["--checkpoint"] = "next to --trace" if trace and stores_data(trace) else "next to --record"
    if not outputs.trajectory_db:  # the application's own, never a home directory's
        outputs = replace(outputs, trajectory_db=str(application_store(app.path)))
        derived["--trajectory-db"] = "the application's own"
    run_files(
        app_inputs(app), trace=outputs.trace, record=outputs.record, checkpoint=outputs.checkpoint,
        resume=resume, trajectory_db=outputs.trajectory_db, extra=settings.backend.extra, derived=derived,
    ).check()
    return replace(settings, outputs=outputs)


def _prepare_resume(app: Application, outputs: Outputs, resume: str, derived: dict[str, str]) -> Outputs:
    """The outputs of a resumed run: its own trace and recording, named after the run it continues
    unless given (and then never that run's)."""
    if not Path(resume).is_file():
        raise CheckpointError(f"--resume {resume}: no such checkpoint file")
    given = outputs.checkpoint
    if given and not same_file(given, resume):
        raise CheckpointError(f"--checkpoint {given}: a resumed run goes on writing the checkpoint it resumes (--resume {resume}); leave --checkpoint out")
    store = CheckpointStore(resume, read_only=True)
    try:
        runs = store.runs()
        left = plan_resume(store, app, full_catalog(), ANSWERS[0], write=False)  # checks it is this application's first
    except sqlite3.Error as error:  # tables of the right names, not of the right shape
        raise CheckpointError(f"--resume {resume}: not a checkpoint of this program ({error})") from None
    finally:
        store.close()
    total = len(app.operations)
    if left.index >= total:  # a run resumed is a run interrupted: one that did everything has nothing to go on with
        raise CheckpointError(f"--resume {resume}: the run it holds did every operation ({total} of {total}): nothing is left to resume; "
                              "run without --resume to start again")
    earlier = [p for _, trace, record in runs for p in (trace, record) if p and stores_data(p)]  # (/dev/null holds no run)
    for option, column in (("trace", 1), ("record", 2)):
        given = getattr(outputs, option)
        last = next((str(r[column]) for r in reversed(runs) if r[column] and stores_data(r[column])), "")
        if given and any(same_file(given, p) for p in earlier):
            raise CheckpointError(f"--{option} {given}: that file holds the run being resumed; give a new file (or leave it out: {next_name(given, len(runs) + 1)})")
        if not given and last:
            outputs = replace(outputs, **{option: next_name(last, len(runs) + 1)})
            derived[f"--{option}"] = "named after the resumed run's"
    return outputs


@dataclass
class Flight:
    """The recorder, checkpoint and resume plan of one run (each None when not asked for)."""

    recorder: Recorder | None = None
    store: CheckpointStore | None = None
    writer: CheckpointWriter | None = None
    resume: ResumePlan | None = None


async def start_recording(
    settings: RunSettings, app: Application, transport: Transport, backend: str, observer: RunObserver | None = None
) -> Flight:
    """Start what the settings ask for: a recorder node, checkpoints fed by ``observer``, the resume plan."""
    flight = Flight()
    path = checkpoint_path(settings)
    outputs = settings.outputs
    continues = ""
    if path:
        resuming = bool(settings.resume)
        if not resuming:
            for suffix in ("", "-wal", "-shm"):  # a fresh run starts a fresh checkpoint
                Path(path + suffix).unlink(missing_ok=True)
        catalog = full_catalog()
        store = flight.store = CheckpointStore(path)
        if resuming:
            flight.resume = plan_resume(store, app, catalog, settings.on_interrupted)
            flight.resume.on_skip = lambda index, op, group: _skipped(store, index, op, group)
            continues = flight.resume.continues
        store.begin_run(app_meta(app), outputs.trace or "", outputs.record or "", continues)
        flight.writer = CheckpointWriter(store, app, catalog)
        if observer is not None:
            observer.sinks.append(flight.writer.on_status)
            observer.event_sinks.append(flight.writer.on_event)
    if outputs.record:
        flight.recorder = record_node(transport.create_node("recorder"), outputs.record, app, backend, continues, derive_tf=True)
    return flight


def _skipped(store: CheckpointStore, index: int, operation: Operation, group: str) -> None:
    """An operator skipped an interrupted function: it counts as done for any later resume."""
    store.function_event(index, operation.id, group, operation.calls[group].function, 0, SKIPPED, 0.0)


def record_node(
    node: Node, path: str, app: Application, backend: str = "ROS 2 bridge node", continues: str = "", *, derive_tf: bool = False,
    option: str = "--record",
) -> Recorder | None:
    """Record the graph ``node`` sees to ``path`` (None when empty); on ROS, the engine's ``record``
    parameter records through the engine's own node.  ``derive_tf``: the bridge runs in this
    process (``run``), so ``tf`` is worked out of its joint states (:mod:`.derived_tf`); on a
    graph, ``tf`` may have other publishers and is recorded as received.  Refused (one line naming
    ``option``) when ``path`` is the application, its cell, a directory or cannot be written."""
    if not path:
        return None
    plan = FilePlan("engine")
    for named, source in app_inputs(app):
        plan.read(named, source)
    plan.write(Output(option, path, "the recording", "run.mcap", joiner="=" if option.startswith("parameter") else " ")).check()
    stream = open(path, "wb")  # noqa: SIM115 - the sink's thread owns and closes it
    recorder = Recorder(node, McapSink(stream, path), derive_tf=derive_tf)
    recorder.describe_run(app.path, app.cell.path if app.cell is not None else None, {
        "application": app.name, "robot": app.robot.name, "backend": backend, "continues": continues,
    }, app.includes, app.iterations())
    recorder.start()
    return recorder


async def stop_recording(flight: Flight | Recorder | None, out: IO[str]) -> list[WriteFailure]:
    """Finish the recording and close the checkpoint; say what they hold. What could not be written
    whole (the command then ends with EXIT_OUTPUT, :class:`WriteFailure`'s line naming the option)."""
    if isinstance(flight, Recorder) or flight is None:
        flight = Flight(recorder=flight)
    failures: list[WriteFailure] = []
    if flight.recorder is not None:
        stats = await flight.recorder.close()
        out.write("\n".join(stats.lines()) + "\n")
        if stats.error or stats.dropped:
            dropped = f" ({sum(stats.dropped.values())} message(s) dropped)" if stats.dropped else ""
            failures.append(WriteFailure("--record", stats.path, stats.error or "the writer could not keep up", f"the recording is incomplete{dropped}"))
    if flight.store is not None:
        if flight.writer is not None and flight.writer.error:
            out.write(f"CHECKPOINT FAILED: {flight.writer.error}\n")
            failures.append(WriteFailure("--checkpoint", str(flight.store.path), flight.writer.reason,
                                         "later results are not in it: a resume from it may redo functions that completed"))
        flight.store.close()
    return failures
