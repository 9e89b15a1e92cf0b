"""What ``run`` needs of the recorder: its command-line options and start/stop around a run.

Kept here so ``cli.py`` only calls :func:`add_run_options`, :func:`start_recording` and
:func:`stop_recording`.
"""
from __future__ import annotations

import argparse
from typing import IO

from execution_engine.app_model import Application
from execution_engine.recorder.recorder import Recorder
from execution_engine.recorder.writer import McapSink
from execution_engine.transport.port import Node, Transport


def add_run_options(run: argparse.ArgumentParser) -> None:
    """``--record PATH``: every topic of the run as MCAP (ROS 2 schemas and CDR, as ``ros2 bag record -s mcap``)."""
    run.add_argument(
        "--record", metavar="RUN.mcap",
        help="record every topic of the run to an MCAP file that Foxglove, PlotJuggler and ros2 bag open "
             "(read it back with: python -m execution_engine report RUN.mcap)",
    )


async def start_recording(
    args: argparse.Namespace, app: Application, transport: Transport, backend: str, continues: str = ""
) -> Recorder | None:
    """A recorder node on ``transport`` writing ``args.record``, or None without ``--record``."""
    path = getattr(args, "record", None)
    if not path:
        return None
    return record_node(transport.create_node("recorder"), path, app, backend, continues)


def record_node(node: Node, path: str, app: Application, backend: str = "ROS 2 bridge node", continues: str = "") -> Recorder | None:
    """Record the graph ``node`` sees to ``path`` (None when empty); on ROS, the engine's ``record``
    parameter records through the engine's own node."""
    if not path:
        return None
    stream = open(path, "wb")  # noqa: SIM115 - the sink's thread owns and closes it
    recorder = Recorder(node, McapSink(stream, path))
    recorder.describe_run(app.path, app.cell.path if app.cell is not None else None, {
        "application": app.name, "robot": app.robot.name, "backend": backend, "continues": continues,
    })
    recorder.start()
    return recorder


async def stop_recording(recorder: Recorder | None, out: IO[str]) -> bool:
    """Finish the file and say what it holds; False when messages were lost."""
    if recorder is None:
        return True
    stats = await recorder.close()
    out.write("\n".join(stats.lines()) + "\n")
    return not stats.dropped and not stats.error
