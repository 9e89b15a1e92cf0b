"""One rule for every file a command writes: checked before anything runs, against every file it reads and every other file it writes.

A run writes up to five files (trace, recording, checkpoint, trajectory database, a bridge's
feedback log), ``report`` a timeline, the studio its runs' files and the applications it saves.
Each is named on a command line or derived from another name (``APP.trajectories.sqlite``,
``RUN.checkpoint.sqlite``), so two of them -- or one of them and the application, its cell or a
configuration the run reads -- can be one file under two names: the same path, a symbolic link, a
hard link, ``./x`` and ``x``.  Writing one would destroy the other, and the damage shows only after
the run.  So the files are compared by what they are, not by how they are spelled: an existing
file by its device and inode, one still to be created by its real path (symbolic links resolved),
and an SQLite file together with the ``-wal``/``-shm``/``-journal`` files SQLite makes beside it.

:class:`FilePlan` collects a command's files -- :meth:`~FilePlan.read` the inputs,
:meth:`~FilePlan.write` the outputs -- and :meth:`~FilePlan.check` refuses, in one line naming
the option and what to do, the first problem: an output that is a directory, lies in a folder
that does not exist, cannot be created or written, is not a regular file where SQLite needs one;
then an output that is the same file as an input or as another output (the line names both).
Nothing is written: for a path that does not exist yet a file of an unused name is created in its
folder and removed again, the only sure test of permissions and read-only mounts.  Files that are not regular files store nothing a
write could destroy: ``/dev/null`` or ``/dev/full`` may be given for more than one output (a
write to ``/dev/full`` then fails during the run and the command ends with its own exit code,
:class:`WriteFailure`); a block device (a disk) is refused, a named pipe nobody reads is refused
instead of waiting for a reader for ever.
"""
from __future__ import annotations

import errno
import os
import sqlite3
import stat
import tempfile
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

#: What SQLite makes beside a database: a write-ahead log and its index, or a rollback journal.
SQLITE_SIDECARS = ("-wal", "-shm", "-journal")
#: Paths SQLite takes for a database that is no file.
NOT_A_FILE = (":memory:", "")
#: The longest file name Linux file systems take (ext4, xfs, btrfs, tmpfs: 255 bytes).
NAME_MAX = 255


class Refused(Exception):
    """An option a command cannot work with; the message is the whole line the operator reads."""


@dataclass(frozen=True)
class Output:
    """A file a command writes.

    ``option`` names it on the command line (``--trace``; ``/api/save``); ``what`` says what it
    holds (``the trace``); ``default`` says where the path came from when the option was not given
    (``next to --record``), and is empty when the option named it."""

    option: str
    path: str
    what: str
    example: str = "run.out"  # a file name to suggest when a directory was given
    sqlite: bool = False  # an SQLite database: a regular file, its sidecars beside it
    reads: bool = False  # the command reads it too (the trajectory database): an existing one must be SQLite
    makes_folders: bool = False  # the writer makes missing folders (the trajectory store does)
    default: str = ""
    joiner: str = " "  # between option and path: "--trace run.jsonl", "--backend-option feedback=f.csv"

    @property
    def named(self) -> str:
        if self.default:
            return f"{self.what} {self.path} ({self.default}; {self.option} names another)"
        return f"{self.option}{self.joiner}{self.path}"


@dataclass(frozen=True)
class Input:
    """A file a command reads: ``named`` is how a line names it (``the application apps_xml/x.xml``)."""

    named: str
    path: str


@dataclass(frozen=True)
class WriteFailure:
    """An output that could not be written during a run (a full disk, a file system gone read-only).

    The run goes on -- the robot is never stopped because a log file failed -- but the command ends
    with ``EXIT_OUTPUT`` (4) unless the run itself failed, and says so in one line."""

    option: str  # --trace, --record, --checkpoint
    path: str
    reason: str  # the system's words: No space left on device
    lost: str  # what is missing: "12 record(s) lost, the trace is incomplete"

    def line(self, outcome: str, summary: str = "summary above") -> str:
        return (f"error: {self.option} {self.path}: could not be written ({self.reason}): {self.lost}; "
                f"the run itself: {outcome.upper()} ({summary}); free space or give another {self.option}")


#: The exit code of a command whose work was done but an output of which could not be written whole.
EXIT_OUTPUT = 4


def identity(path: str | Path) -> tuple[object, ...]:
    """What a path is: (device, inode) for an existing file, the real path for one to be created."""
    try:
        st = os.stat(path)
    except OSError:
        return ("new", os.path.realpath(path))
    return ("file", st.st_dev, st.st_ino)


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether ``a`` and ``b`` are (or would be) one file, whatever their spelling."""
    return identity(a) == identity(b)


def stores_data(path: str | Path) -> bool:
    """A regular file, or a path still to be created: a write there replaces what is stored."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return True


class FilePlan:
    """The files one command reads and writes; :meth:`check` before anything runs."""

    def __init__(self, command: str = "run") -> None:
        self.command = command  # "run", "report", "studio run": how a line names who reads a file
        self.inputs: list[Input] = []
        self.outputs: list[Output] = []

    def read(self, named: str, path: str | Path | None) -> FilePlan:
        if path is not None and str(path) not in NOT_A_FILE:
            self.inputs.append(Input(named, str(path)))
        return self

    def write(self, output: Output | None) -> FilePlan:
        if output is not None and not (output.sqlite and output.path in NOT_A_FILE):
            self.outputs.append(output)
        return self

    def check(self) -> None:
        """Refused (one line) at the first problem: each output's own, then clashes, then writability."""
        for output in self.outputs:
            check_kind(output)
        self.check_clashes()
        for output in self.outputs:
            check_contents(output)
            check_writable(output)

    def check_clashes(self) -> None:
        """Refused when an output (or a file SQLite makes beside it) is an input or another output."""
        for index, output in enumerate(self.outputs):
            for path, suffix in _spellings(output):
                for source in self.inputs:
                    if stores_data(source.path) and same_file(path, source.path):
                        raise Refused(
                            f"{_head(output, suffix, source.named, '')}, which this {self.command} reads; "
                            f"{output.what} would overwrite it: give another file"
                        )
                for other in self.outputs[:index]:
                    for other_path, other_suffix in _spellings(other):
                        if stores_data(path) and same_file(path, other_path):
                            # the line's subject: an option given before a path derived from one, the later of two given
                            first, second = (other, output) if bool(other.default) >= bool(output.default) else (output, other)
                            s1, s2 = (other_suffix, suffix) if first is other else (suffix, other_suffix)
                            raise Refused(
                                f"{_head(second, s2, first.named, s1, first.path)}; "
                                f"{second.what} and {first.what} would overwrite each other: give each its own file"
                            )


def _spellings(output: Output) -> list[tuple[str, str]]:
    """The file itself, and for SQLite each file it makes beside it (with its suffix)."""
    return [(output.path, "")] + ([(output.path + suffix, suffix) for suffix in SQLITE_SIDECARS] if output.sqlite else [])


def _head(subject: Output, suffix: str, other: str, other_suffix: str, other_path: str = "") -> str:
    """``--record X: is the same file as --trace X``, naming SQLite's files beside a database where they clash."""
    named = f"SQLite's {other_path}{other_suffix} beside {other}" if other_suffix else other
    if suffix:
        return f"{subject.named}: SQLite's {subject.path}{suffix} beside it is the same file as {named}"
    return f"{subject.named}: is the same file as {named}"


# ----------------------------------------------------------------------------- each output
def check_kind(output: Output) -> None:
    """What an output is, before it is compared with anything: not a directory, its folder there, the right kind."""
    target = Path(output.path)
    for part in target.parts:  # before anything looks at the path: a stat of a name too long raises
        if len(os.fsencode(part)) > NAME_MAX:
            raise Refused(f"{output.named}: cannot be created (file name too long: {part[:20]}... has more than {NAME_MAX} bytes); give a shorter name")
    if target.is_dir() or not target.name:
        an = "an SQLite file" if output.sqlite else "a file name"
        raise Refused(f"{output.named}: is a directory; give {an}, e.g. {os.path.join(output.path, output.example)}")
    if not output.makes_folders:
        parent = target.parent
        if not parent.exists():
            raise Refused(f"{output.named}: the directory {parent} does not exist; create it first or give another path")
        if not parent.is_dir():
            raise Refused(f"{output.named}: {parent} is not a directory")
    try:
        mode = os.stat(target).st_mode
    except OSError:
        return  # to be created: check_writable tries
    if stat.S_ISBLK(mode):
        raise Refused(f"{output.named}: is a block device (a disk), not a file; give a file")
    if output.sqlite and not stat.S_ISREG(mode):
        raise Refused(f"{output.named}: is not a regular file; give an SQLite file")


def check_contents(output: Output) -> None:
    """An output the command also reads (the trajectory database) holds what it should, or nothing yet."""
    target = Path(output.path)
    if output.reads and output.sqlite and target.is_file():
        try:  # read-only: a refused file is left exactly as it was
            with closing(sqlite3.connect(f"{target.resolve().as_uri()}?mode=ro", uri=True)) as db:
                db.execute("SELECT count(*) FROM sqlite_master").fetchone()
        except sqlite3.Error as error:  # sqlite3.DatabaseError is no OSError
            raise Refused(f"{output.named}: is not an SQLite database ({error}); give the file RecordTrajectory wrote, or a new name") from None


def _open_for_append(output: Output, target: Path) -> None:
    """An existing file can be written: opened for appending, which changes nothing."""
    try:
        with open(target, "ab"):
            pass
    except OSError as error:
        raise Refused(f"{output.named}: cannot be written ({error.strerror or error}); give a writable file") from None


def check_writable(output: Output) -> None:
    """Open an existing output for appending (changes nothing), or check a new one can be made in its folder."""
    target = Path(output.path)
    try:
        mode: int | None = os.stat(target).st_mode
    except OSError:
        mode = None
    if mode is not None and stat.S_ISREG(mode):
        _open_for_append(output, target)
        return
    if mode is not None:  # a device or a pipe: opened without waiting for a reader, closed again
        try:
            os.close(os.open(target, os.O_WRONLY | os.O_NONBLOCK))
        except OSError as error:
            why = "a named pipe nobody reads" if error.errno == errno.ENXIO and stat.S_ISFIFO(mode) else error.strerror or str(error)
            raise Refused(f"{output.named}: cannot be written ({why}); give a writable file") from None
        return
    if output.makes_folders:
        existing = target.parent
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
        if not existing.is_dir():
            raise Refused(f"{output.named}: {existing} is not a directory")
        if existing != target.parent:
            if not os.access(existing, os.W_OK | os.X_OK):
                raise Refused(f"{output.named}: the directory {target.parent} cannot be created in {existing}")
            return
    _probe_folder(output, target)


def _probe_folder(output: Output, target: Path) -> None:
    """A new file can be made there: a file of a name nobody else uses is created in its folder and removed again.

    The target's own name is never created by the check: another run of the same application may
    make that very file (``APP.trajectories.sqlite``) between this create and its removal, and
    the removal would then delete the other run's database -- or the other run's check would find
    this one's probe and take it for something that cannot be written.  The name itself was checked
    against the folder's limit by :func:`check_kind`, the one way a name fails where another succeeds.
    """
    target = Path(os.path.realpath(target))  # a dangling symbolic link is written where it points
    folder = target.parent
    try:
        fd, probe = tempfile.mkstemp(prefix=".write-check-", dir=folder)
    except OSError as error:
        raise Refused(f"{output.named}: cannot be created ({error.strerror or error}); give a writable path") from None
    os.close(fd)
    os.unlink(probe)
