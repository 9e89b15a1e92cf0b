"""The real-time loop in a process of its own: ``python -m robot_bridges.kuka_rsi.rt_process``.

Started by :class:`~robot_bridges.kuka_rsi.interface.RsiInterface` with two inherited file
descriptors -- a ``memfd`` holding the shared records and one end of the message pipe -- and the
robots and settings pickled on stdin.  A plain subprocess rather than ``multiprocessing``:
nothing of the application's ``__main__`` is imported again, and when the child dies for any
reason its end of the pipe closes, which the application sees at once.
"""
from __future__ import annotations

import mmap
import os
import pickle
import socket
import subprocess
import sys
from collections.abc import Sequence

from robot_bridges.kuka_rsi.external import LoopSettings, RobotLink, RsiLoop
from robot_bridges.kuka_rsi.pipe import FramedPipe
from robot_bridges.kuka_rsi.slots import layout


def spawn(links: Sequence[RobotLink], settings: LoopSettings, size: int) -> tuple[subprocess.Popen[bytes], mmap.mmap, socket.socket]:
    """Start the loop process; returns it, the shared buffer and the application's end of the pipe."""
    memfd = os.memfd_create("rsi-records", os.MFD_CLOEXEC)
    try:
        os.ftruncate(memfd, size)
        buffer = mmap.mmap(memfd, size)
        ours, theirs = FramedPipe.pair()
        try:
            process = subprocess.Popen(
                [sys.executable, "-m", "robot_bridges.kuka_rsi.rt_process", str(memfd), str(theirs.fileno()), str(size)],
                stdin=subprocess.PIPE,
                pass_fds=(memfd, theirs.fileno()),
            )
        finally:
            theirs.close()
        assert process.stdin is not None
        process.stdin.write(pickle.dumps((tuple(links), settings)))
        process.stdin.close()
        return process, buffer, ours
    finally:
        os.close(memfd)


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 3:
        print("usage: python -m robot_bridges.kuka_rsi.rt_process MEMFD PIPEFD SIZE (started by RsiInterface)", file=sys.stderr)
        return 1
    memfd, pipefd, size = (int(a) for a in args)
    links, settings = pickle.loads(sys.stdin.buffer.read())  # from our own parent, not from outside
    buffer = mmap.mmap(memfd, size)
    os.close(memfd)
    sock = socket.socket(fileno=pipefd)
    view = memoryview(buffer)
    try:
        slots = layout(view, len(links))
        RsiLoop(links, settings, slots, FramedPipe(sock, blocking_send=False)).run()
        del slots
    finally:
        sock.close()
        view.release()
        buffer.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
