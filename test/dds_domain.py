"""A DDS domain of a test's own: no two tests running at once -- in this session or in another on the same host -- share one.

Participants in one domain on one host find each other (loopback, the localhost peer): a test that
shared its domain with another saw that test's nodes -- a second engine, a bridge whose arms are
elsewhere -- and a cell checked from the wrong robot's joints refused or ran what it should not.
Picking a random id among the 133 free ones (100..232) made that a matter of luck whenever two
sessions ran at once (a helper's tests beside the full suite).  So a test *claims* its domain: an
exclusive ``flock`` on a lock file per id, in a folder every session of this user shares, held for
as long as the test uses the domain and released by the kernel when the holder ends, however it
ends (no stale claim outlives a killed session).  An id whose lock is held is skipped.

Processes a test starts must not outlive its claim in the domain: tests that start them stop them
(:func:`stop_group` ends a whole process group, a launch and the nodes it started).
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import random
import signal
import subprocess
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

#: Domain ids the tests use: above the usual ones (0, and the few a lab picks), up to rmw's 232.
FIRST, LAST = 100, 232
#: Cyclone on loopback only (the transport adds the localhost peer for LOCALHOST).
LOOPBACK = '<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces></General></Domain></CycloneDDS>'


class NoFreeDomain(RuntimeError):
    """Every domain id of the range is claimed by a running test."""


def _folder() -> Path:
    folder = Path(tempfile.gettempdir()) / f"dual_arm_executive-dds-domains-{os.getuid()}"
    folder.mkdir(mode=0o700, exist_ok=True)
    return folder


@contextlib.contextmanager
def claimed_domain(folder: Path | None = None, ids: Sequence[int] = range(FIRST, LAST + 1)) -> Iterator[int]:
    """A domain id no other test uses while the ``with`` block runs (random among the free ones).
    ``folder`` and ``ids``: the claims and the ids to claim from (the allocator's own test keeps its own)."""
    folder = folder or _folder()
    ids = list(ids)
    random.SystemRandom().shuffle(ids)  # not the test's random: a seeded one would make every session pick alike
    for domain in ids:
        fd = os.open(folder / f"{domain}.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        try:
            yield domain
        finally:
            os.close(fd)  # closing the last descriptor releases the lock
        return
    raise NoFreeDomain(f"all {len(ids)} DDS domain ids {min(ids, default=0)}..{max(ids, default=0)} are claimed by running tests")


_HELD: list[contextlib.ExitStack] = []


def hold_domain() -> int:
    """A domain claimed for the rest of this process (a bench's): the kernel gives it back when the process ends."""
    stack = contextlib.ExitStack()
    domain = stack.enter_context(claimed_domain())
    _HELD.append(stack)
    return domain


def dds_env(domain: int, interfaces: str = LOOPBACK) -> dict[str, str]:
    """The environment of a participant of ``domain``: this host only, loopback only."""
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "CYCLONEDDS_URI": interfaces}


@contextlib.contextmanager
def domain_env() -> Iterator[dict[str, str]]:
    """:func:`dds_env` of a domain claimed for the ``with`` block."""
    with claimed_domain() as domain:
        yield dds_env(domain)


def stop_group(process: subprocess.Popen[str] | subprocess.Popen[bytes], grace: float = 5.0) -> None:
    """End ``process`` and every process of its group (start it with ``start_new_session=True``):
    SIGTERM, SIGKILL after ``grace`` s; nothing of it is left in the domain afterwards."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)
        try:
            process.wait(grace)
            break
        except subprocess.TimeoutExpired:
            continue
    with contextlib.suppress(ProcessLookupError):  # the nodes a launch started, if it ended before them
        os.killpg(process.pid, signal.SIGKILL)


def run_group(argv: Sequence[str], cwd: Path, env: dict[str, str], timeout: float) -> tuple[int, str]:
    """Run ``argv`` (a ``launch``: it starts processes of its own) in a process group of its own, its output and
    errors as one text; whatever is left of the group is ended afterwards (:func:`stop_group`).  Exit code, output."""
    process = subprocess.Popen(
        list(argv), cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True,
    )
    try:
        out, _ = process.communicate(timeout=timeout)
    finally:
        stop_group(process)
    return process.returncode, out
