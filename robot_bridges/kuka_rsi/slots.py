"""Lock-free records shared by the real-time loop and the application: one writer, any readers.

``set_cart_pos`` must cost microseconds and must never make the loop wait, and the loop may run
in another process.  So commands and feedback go through fixed records in one shared buffer (a
``bytearray`` for a loop thread, :class:`multiprocessing.shared_memory.SharedMemory` for a loop
process), each guarded by a sequence counter -- a seqlock: the writer makes the counter odd,
writes, makes it even; a reader that sees an odd or changed counter knows the record was torn
and reads again.  Nobody ever blocks on a lock.

The counter is written with native alignment and size (one machine store) and the records lie at
8-byte offsets.  Each record has exactly one writer (the application holds a lock among its own
threads; the loop is a single thread).
"""
from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass

_SEQ = struct.Struct("@Q")


class SlotBusy(RuntimeError):
    """A record stayed half-written for longer than a reader is willing to spin."""


class SeqSlot:
    """One record ``fmt`` (struct format, standard sizes) at ``offset`` of ``buffer``."""

    def __init__(self, buffer: memoryview, offset: int, fmt: str) -> None:
        if offset % 8:
            raise ValueError(f"slot offset {offset} is not 8-byte aligned")
        self._buf = buffer
        self._off = offset
        self._data = offset + 8
        self._struct = struct.Struct("=" + fmt)
        self.size = 8 + (self._struct.size + 7) // 8 * 8
        self._seq = _SEQ.unpack_from(buffer, offset)[0] & ~1

    @staticmethod
    def size_of(fmt: str) -> int:
        return 8 + (struct.calcsize("=" + fmt) + 7) // 8 * 8

    def write(self, *values: object) -> None:
        """Publish ``values``; only the record's single writer may call this."""
        seq = self._seq + 1
        _SEQ.pack_into(self._buf, self._off, seq)
        self._struct.pack_into(self._buf, self._data, *values)
        self._seq = seq + 1
        _SEQ.pack_into(self._buf, self._off, self._seq)

    def version(self) -> int:
        """The counter: changes with every write; odd while a write is under way."""
        return int(_SEQ.unpack_from(self._buf, self._off)[0])

    def try_read(self) -> tuple[int, tuple[object, ...]] | None:
        """``(version, values)``, or None when a write is under way (the loop never spins)."""
        before = _SEQ.unpack_from(self._buf, self._off)[0]
        if before & 1:
            return None
        values = self._struct.unpack_from(self._buf, self._data)
        if _SEQ.unpack_from(self._buf, self._off)[0] != before:
            return None
        return int(before), values

    def read(self, spins: int = 10_000) -> tuple[int, tuple[object, ...]]:
        """``(version, values)``; yields the CPU between attempts so a preempted writer can finish."""
        for attempt in range(spins):
            got = self.try_read()
            if got is not None:
                return got
            if attempt > 8:
                os.sched_yield()  # releases the GIL too, in case the writer is a thread of ours
        raise SlotBusy(f"record at offset {self._off} stayed busy for {spins} reads")


# ------------------------------------------------------------------------------ the records
#: kind, command id, 7 values (6 joints, or x y z qx qy qz qw), 4 limits.
COMMAND_FORMAT = "qq7d4d"
#: bits of the RECEIVE booleans the application sets (handshake flags, tool outputs, Stop).
FLAGS_FORMAT = "Q"
#: t_ns, ipoc, cycles, delay, status bits, send-boolean bits, done id, done result, active id,
#: rejected packets, limiter clamps, then RIst (m, rad), RSol, AIPos (rad), ASPos, and the joint
#: set point the external system commands (rad): 30 doubles.
STATE_FORMAT = "qqqqQQqqqqq30d"
#: the operator's speed override: the rate (0..1) every motion of the robot plays at, on its path.
OVERRIDE_FORMAT = "d"


class CommandKind:
    NONE = 0
    JOINT = 1  # values[0:6] joint target (rad); limits: speed (rad/s), accel (rad/s^2)
    CART = 2  # values: x y z (m), quaternion; limits: speed, accel, angular speed, angular accel
    HALT = 3  # brake to rest, forget the target
    STREAM = 4  # play the path staged under id values[0]


class Status:
    CONNECTED = 1  # packets arrive
    MOVING = 2  # a generator or a stream is running
    CORRECTING = 4  # the robot follows corrections (RSI_MOVECORR, or no handshake configured)
    LOST = 8  # packets stopped arriving
    HALTED = 16  # a halt is braking or holding


@dataclass(frozen=True)
class RobotSlots:
    """The four records of one robot."""

    command: SeqSlot
    flags: SeqSlot
    state: SeqSlot
    override: SeqSlot


def robot_block_size() -> int:
    return SeqSlot.size_of(COMMAND_FORMAT) + SeqSlot.size_of(FLAGS_FORMAT) + SeqSlot.size_of(STATE_FORMAT) + SeqSlot.size_of(OVERRIDE_FORMAT)


def layout(buffer: memoryview, robots: int) -> list[RobotSlots]:
    """The records of ``robots`` robots, packed from offset 0 of ``buffer``."""
    out: list[RobotSlots] = []
    offset = 0
    for _ in range(robots):
        command = SeqSlot(buffer, offset, COMMAND_FORMAT)
        offset += command.size
        flags = SeqSlot(buffer, offset, FLAGS_FORMAT)
        offset += flags.size
        state = SeqSlot(buffer, offset, STATE_FORMAT)
        offset += state.size
        override = SeqSlot(buffer, offset, OVERRIDE_FORMAT)
        offset += override.size
        out.append(RobotSlots(command, flags, state, override))
    if offset > len(buffer):
        raise ValueError(f"{robots} robots need {offset} bytes of shared buffer, have {len(buffer)}")
    return out


def bits(values: Sequence[bool]) -> int:
    out = 0
    for i, v in enumerate(values):
        if v:
            out |= 1 << i
    return out
