"""The AdeptServer wire format (pyadept / AdeptServer, seed 000): command messages, acks, framing.

Everything on the wire is ASCII, one message per line, delimited by ``\\r\\n``::

    <id>:<skill>[:<a>,<b>,...]\\r\\n                       client -> server (a command message)
    <id>:done:<t_recv>,<t_done>:<x>,<y>,<z>,<yaw>,<pitch>,<roll>\\r\\n   server -> client (the ack)

Numbers are written with three decimals (pyadept ``'{:.3f}'``, V+ ``$ENCODE(/F0.3, ...)``).
``set_speed`` is written as an integer percentage when it is one -- the seed's grammar and
pyadept's ``SetSpeed`` (``'{:d}'``) -- and with three decimals otherwise, which V+ ``VAL`` and
``SPEED`` accept, so speeds below 1 % remain expressible.

**Ids.** pyadept makes an id from the first 8 characters of ``str(uuid.uuid4())`` -- eight lowercase
hex digits -- and :func:`new_id` does the same.  The server never interprets the id: AdeptServer
splits the line on ``:`` and echoes field 0 back verbatim.  So the codec treats an id as an
opaque token of 1 to :data:`MAX_ID_LENGTH` ASCII letters and digits.  That is why the seed's
``nee861124:break`` (nine characters, not hex: most likely a stray ``n`` from the ``\\r\\n``
printed before it) still encodes byte for byte, while an id that could break the framing (``:``,
whitespace, control bytes) is refused.

TCP is a byte stream, so :class:`LineSplitter` reassembles lines across any segmentation, with
a bound on line length.  Malformed input raises :class:`DecodeError` naming the offending line;
an unknown skill raises the subclass :class:`UnknownSkill`, because the server must treat it
differently (the real one never acks it).
"""
from __future__ import annotations

import math
import random
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

DELIMITER = b"\r\n"
#: Longest line accepted on either side.  The longest legal message is ~100 bytes and V+ strings
#: hold 128 characters; anything much longer is garbage or an attack, not a message.
MAX_LINE = 256
MAX_ID_LENGTH = 16
#: Numbers are single-precision reals on the controller; beyond this they are nonsense anyway.
MAX_ABS_VALUE = 1e6
#: Controller timestamps count seconds since the server started; a year is far beyond any session.
MAX_TIMESTAMP = 1e8

_ID = re.compile(r"[0-9A-Za-z]{1,%d}" % MAX_ID_LENGTH)
_NUMBER = re.compile(r"-?[0-9]{1,10}(\.[0-9]{1,6})?")
_STATUS = re.compile(r"[a-z_]{1,16}")


class Skill(str, Enum):
    """The AdeptServer skills (V+ programs called by name with ``CALLS``)."""

    MOVE_TO = "move_to"
    MOVE_REL_WORLD = "move_rel_world"
    MOVE_REL_TOOL = "move_rel_tool"
    MOVE_JOINTS = "move_joints"
    MOVE_REL_JOINTS = "move_rel_joints"
    BREAK = "break"
    SET_SPEED = "set_speed"
    MONITOR_SPEED = "monitor_speed"  # V+ SPEED s MONITOR: the operator's speed override, the running motion included
    ENABLE_AIR = "enable_air"
    DISABLE_AIR = "disable_air"
    GRIPPER_OPEN = "gripper_open"
    GRIPPER_CLOSE = "gripper_close"
    MOVEHOME = "movehome"


#: Skills whose six arguments are a pose (x, y, z mm; yaw, pitch, roll deg) or joints (deg).
MOTION_SKILLS = frozenset(
    {Skill.MOVE_TO, Skill.MOVE_REL_WORLD, Skill.MOVE_REL_TOOL, Skill.MOVE_JOINTS, Skill.MOVE_REL_JOINTS}
)
ARITY: dict[Skill, int] = {s: (6 if s in MOTION_SKILLS else 1 if s in (Skill.SET_SPEED, Skill.MONITOR_SPEED) else 0) for s in Skill}
_SKILLS = {s.value: s for s in Skill}


class DecodeError(ValueError):
    """A line that is not a valid message; carries the offending bytes for the report."""

    def __init__(self, reason: str, line: bytes = b"") -> None:
        shown = line[:80] + (b"..." if len(line) > 80 else b"")
        super().__init__(f"{reason} in {shown!r}" if line else reason)
        self.reason = reason
        self.line = line


class UnknownSkill(DecodeError):
    """A well-formed message naming a skill the server does not have."""

    def __init__(self, reason: str, line: bytes, msg_id: str, skill: str) -> None:
        super().__init__(reason, line)
        self.msg_id = msg_id
        self.skill = skill


class FrameError(DecodeError):
    """The byte stream itself is broken (an over-long line): the connection cannot be trusted."""


# ----------------------------------------------------------------------------------- ids
#: Where ids come from: 32 random bits per message, from a generator seeded by the system's entropy
#: once.  An id only has to differ from the ids still in flight or recently given up on (the
#: client checks that); nothing is protected by its being unguessable, and a system call per
#: message (os.urandom) is not needed for that.
_IDS = random.Random()


def new_id() -> str:
    """An id as pyadept makes one: 8 random lowercase hex digits.

    pyadept takes the first 8 characters of ``str(uuid.uuid4())``; those are 32 random bits (the
    version nibble comes later), so 32 random bits in hex are the same thing, at a fraction of
    the cost.
    """
    return f"{_IDS.getrandbits(32):08x}"


def check_id(msg_id: str) -> str:
    # isalnum + isascii is the same test as the _ID pattern, at a third of its cost (hot path)
    if not (isinstance(msg_id, str) and 0 < len(msg_id) <= MAX_ID_LENGTH and msg_id.isascii() and msg_id.isalnum()):
        raise ValueError(f"message id must be 1-{MAX_ID_LENGTH} ASCII letters or digits, got {msg_id!r}")
    return msg_id


# ------------------------------------------------------------------------------ numbers
def format_number(value: float, limit: float = MAX_ABS_VALUE) -> str:
    """Three decimals, as pyadept writes them; ``-0.000`` is written ``0.000``."""
    if not math.isfinite(value) or abs(value) >= limit:
        raise ValueError(f"number must be finite and below {limit:g} in magnitude, got {value!r}")
    text = f"{value:.3f}"
    return "0.000" if text == "-0.000" else text


_ACK_FORMAT = "%s:%s:%.3f,%.3f:%.3f,%.3f,%.3f,%.3f,%.3f,%.3f"


def _within(values: Sequence[float], limit: float) -> bool:
    """Every value finite and below ``limit`` in magnitude (format_number's test, for several at once)."""
    return all(math.isfinite(v) and abs(v) < limit for v in values)


def _parse_numbers(text: str, count: int, what: str, line: bytes) -> tuple[float, ...]:
    parts = text.split(",")
    if len(parts) != count:
        raise DecodeError(f"{what}: expected {count} comma-separated numbers, got {len(parts)}", line)
    for part in parts:
        if not _NUMBER.fullmatch(part):
            raise DecodeError(f"{what}: {part!r} is not a decimal number", line)
    return tuple(float(p) for p in parts)


def _ascii(line: bytes) -> str:
    if len(line) > MAX_LINE:
        raise FrameError(f"line of {len(line)} bytes exceeds the {MAX_LINE}-byte limit", line)
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        raise DecodeError("non-ASCII bytes", line) from None
    if not text.isprintable():
        raise DecodeError("control characters inside a message", line)
    return text


# ----------------------------------------------------------------------------- commands
@dataclass(frozen=True)
class Command:
    """One skill invocation without its id: what a single command message asks for."""

    skill: Skill
    args: tuple[float, ...] = ()
    _wire: bytes = field(default=b"", init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        skill = Skill(self.skill)
        object.__setattr__(self, "skill", skill)
        args = tuple(float(a) for a in self.args)
        object.__setattr__(self, "args", args)
        if len(args) != ARITY[skill]:
            raise ValueError(f"{skill.value} takes {ARITY[skill]} arguments, got {len(args)}")
        for a in args:
            format_number(a)  # finite and bounded, or ValueError
        if skill is Skill.SET_SPEED and not (0 < args[0] <= 100):
            raise ValueError(f"set_speed takes a percentage in (0, 100], got {args[0]!r}")
        if skill is Skill.MONITOR_SPEED and not (0 <= args[0] <= 100):
            raise ValueError(f"monitor_speed takes a percentage in [0, 100], got {args[0]!r}")
        # Encoded once: a command is immutable, and the client writes the same ones again and again.
        object.__setattr__(self, "_wire", b":" + self.payload().encode("ascii") + DELIMITER)

    @property
    def is_motion(self) -> bool:
        return self.skill in MOTION_SKILLS or self.skill is Skill.MOVEHOME

    def payload(self) -> str:
        """The part after the id: ``skill[:args]``."""
        if not self.args:
            return self.skill.value
        if self.skill in (Skill.SET_SPEED, Skill.MONITOR_SPEED) and self.args[0] == int(self.args[0]):
            return f"{self.skill.value}:{int(self.args[0])}"  # the seed's grammar: an integer
        return f"{self.skill.value}:{','.join(format_number(a) for a in self.args)}"

    def __str__(self) -> str:
        return self.payload()


@dataclass(frozen=True, slots=True)  # slots: one per message written, one Ack per line read
class Message:
    """A command message: an id and the command it carries."""

    id: str
    command: Command

    def __post_init__(self) -> None:
        check_id(self.id)

    def encode(self) -> bytes:
        return self.id.encode("ascii") + self.command._wire

    def __str__(self) -> str:
        return f"{self.id}:{self.command.payload()}"


def encode_messages(messages: Sequence[Message]) -> bytes:
    """Several messages in one byte string, for one write (pyadept's ``cmdexec_joined``)."""
    return b"".join(m.encode() for m in messages)


#: Commands already decoded, by the text after the id: a server reads the same few (break, speeds,
#: gripper) again and again, and a command is immutable.  Only commands that decoded cleanly go in;
#: bounded, and emptied when full.
_DECODED: dict[str, Command] = {}
_DECODED_MAX = 1024


def decode_message(line: bytes) -> Message:
    """Parse one command message (without its delimiter), as the server does."""
    text = _ascii(line)
    parts = text.split(":")
    if len(parts) < 2 or len(parts) > 3:
        raise DecodeError("expected <id>:<skill>[:<args>]", line)
    msg_id = parts[0]
    if not _ID.fullmatch(msg_id):
        raise DecodeError(f"bad message id {msg_id!r}", line)
    payload = text[len(msg_id) + 1:]
    known = _DECODED.get(payload)
    if known is not None:
        return Message(msg_id, known)
    skill = _SKILLS.get(parts[1])
    if skill is None:
        raise UnknownSkill(f"unknown skill {parts[1]!r}", line, msg_id, parts[1])
    arity = ARITY[skill]
    if arity == 0:
        if len(parts) == 3:
            raise DecodeError(f"{skill.value} takes no arguments", line)
        return Message(msg_id, _remember(payload, Command(skill)))
    if len(parts) != 3:
        raise DecodeError(f"{skill.value} needs {arity} argument(s)", line)
    args = _parse_numbers(parts[2], arity, skill.value, line)
    try:
        return Message(msg_id, _remember(payload, Command(skill, args)))
    except ValueError as error:
        raise DecodeError(str(error), line) from None


def _remember(payload: str, command: Command) -> Command:
    if len(_DECODED) >= _DECODED_MAX:
        _DECODED.clear()
    _DECODED[payload] = command
    return command


# --------------------------------------------------------------------------------- acks
@dataclass(frozen=True, slots=True)
class Ack:
    """The server's acknowledgement of one message.

    ``t_recv`` is when the server read the chunk that held the message and ``t_done`` when the
    skill returned, both in seconds of the controller clock since the server started.  ``pose``
    is where the robot was at ``t_done``: x, y, z (mm), yaw, pitch, roll (deg, V+ Z-Y-Z).
    """

    id: str
    t_recv: float
    t_done: float
    pose: tuple[float, float, float, float, float, float]
    status: str = "done"

    def encode(self) -> bytes:
        t_recv, t_done, pose = self.t_recv, self.t_done, self.pose
        if not (len(pose) == 6 and _within(pose, MAX_ABS_VALUE) and _within((t_recv, t_done), MAX_TIMESTAMP)):
            times = f"{format_number(t_recv, MAX_TIMESTAMP)},{format_number(t_done, MAX_TIMESTAMP)}"  # raises the ValueError
            return f"{self.id}:{self.status}:{times}:{','.join(format_number(v) for v in pose)}".encode("ascii") + DELIMITER
        # every number as format_number writes it, in one formatting: a lone "-0.000" (and only a
        # negative zero is written so with three decimals) becomes "0.000"
        text = _ACK_FORMAT % (self.id, self.status, t_recv, t_done, *pose)
        if "-0.000" in text:
            text = ":".join(",".join("0.000" if n == "-0.000" else n for n in part.split(",")) for part in text.split(":"))
        return text.encode("ascii") + DELIMITER


_NUM = rb"-?[0-9]{1,10}(?:\.[0-9]{1,6})?"  # no groups: the line is split once it has matched
_ACK_LINE = re.compile(rb"[0-9A-Za-z]{1,%d}:[a-z_]{1,16}:%s,%s:%s" % (MAX_ID_LENGTH, _NUM, _NUM, b",".join([_NUM] * 6)))


#: The last pose read, as written and as numbers: an arm at rest (speed, gripper, air, the break
#: after an arrival) acks one after the other with the same pose, which is then not read again.
#: One tuple, replaced whole, so a reader in another thread sees a matching pair.
_last_pose: tuple[bytes, tuple[float, float, float, float, float, float]] = (b"", (0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def decode_ack(line: bytes) -> Ack:
    """Parse one ack line (without its delimiter), as the client does.

    The whole line is matched against the ack's grammar first, every number included; only a
    line that passes it is taken apart (by the fields that failed, in :func:`decode_ack_by_fields`,
    otherwise)."""
    global _last_pose
    if _ACK_LINE.fullmatch(line) is None:
        return decode_ack_by_fields(line)
    msg_id, status, times, written = line.split(b":")
    t_recv, t_done = times.split(b",")
    seen, pose = _last_pose
    if written != seen:
        x, y, z, yaw, pitch, roll = written.split(b",")
        pose = (float(x), float(y), float(z), float(yaw), float(pitch), float(roll))
        _last_pose = (written, pose)
    return Ack(msg_id.decode("ascii"), float(t_recv), float(t_done), pose, "done" if status == b"done" else status.decode("ascii"))


def decode_ack_by_fields(line: bytes) -> Ack:
    """Field by field, to say exactly what is wrong with a line the fast path refused."""
    text = _ascii(line)
    parts = text.split(":")
    if len(parts) != 4:
        raise DecodeError("expected <id>:<status>:<t_recv>,<t_done>:<x,y,z,yaw,pitch,roll>", line)
    msg_id, status, times, pose = parts
    if not _ID.fullmatch(msg_id):
        raise DecodeError(f"bad message id {msg_id!r}", line)
    if not _STATUS.fullmatch(status):
        raise DecodeError(f"bad status {status!r}", line)
    t_recv, t_done = _parse_numbers(times, 2, "timestamps", line)
    values = _parse_numbers(pose, 6, "pose", line)
    return Ack(msg_id, t_recv, t_done, values, status)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------ framing
class LineSplitter:
    """Reassemble ``\\r\\n``-delimited lines from a byte stream cut anywhere.

    ``feed`` returns the complete lines (without delimiters, empty lines dropped) and keeps the
    tail for the next call.  A line longer than ``max_line`` raises :class:`FrameError`: the
    peer is not speaking this protocol, and buffering without bound would let it exhaust memory.
    """

    def __init__(self, max_line: int = MAX_LINE) -> None:
        if max_line < 8:
            raise ValueError(f"max_line must be at least 8 bytes, got {max_line}")
        self.max_line = max_line
        self._tail = b""

    @property
    def pending(self) -> bytes:
        """Bytes of an incomplete line held for the next ``feed``."""
        return self._tail

    def feed(self, data: bytes) -> list[bytes]:
        end = len(data) - 2
        if data.find(DELIMITER) == end and 0 < end <= self.max_line and not self._tail:
            return [data[:end]]  # the common case: one whole line per segment
        buffer = self._tail + data if self._tail else bytes(data)
        if DELIMITER not in buffer:
            self._check(buffer)
            self._tail = buffer
            return []
        *lines, tail = buffer.split(DELIMITER)
        self._check(tail)
        for line in lines:
            self._check(line)
        self._tail = tail
        return [line for line in lines if line]

    def _check(self, chunk: bytes) -> None:
        # +1: a tail may end with the '\r' of a delimiter whose '\n' is still in flight.
        if len(chunk) > self.max_line + 1:
            self._tail = b""
            raise FrameError(f"no delimiter within {self.max_line} bytes", chunk)


# ----------------------------------------------------------------------------- builders
Vector6 = Sequence[float]


def _vector(values: Vector6, what: str) -> tuple[float, ...]:
    values = tuple(float(v) for v in values)
    if len(values) != 6:
        raise ValueError(f"{what} needs 6 values, got {len(values)}")
    return values


def motion(skill: Skill, values: Vector6, *, brk: bool = True) -> tuple[Command, ...]:
    """A motion command, followed by ``break`` unless ``brk`` is False (pyadept ``MotionCommand``).

    ``break`` makes the server wait until the robot has arrived, so consecutive motions are not
    blended and the ack of ``break`` reports the reached pose.
    """
    if skill not in MOTION_SKILLS:
        raise ValueError(f"{skill} is not a motion skill")
    move = Command(skill, _vector(values, skill.value))
    return (move, BREAK) if brk else (move,)


def move_to(pose: Vector6, *, brk: bool = True) -> tuple[Command, ...]:
    return motion(Skill.MOVE_TO, pose, brk=brk)


def move_rel_world(delta: Vector6, *, brk: bool = True) -> tuple[Command, ...]:
    return motion(Skill.MOVE_REL_WORLD, delta, brk=brk)


def move_rel_tool(delta: Vector6, *, brk: bool = True) -> tuple[Command, ...]:
    return motion(Skill.MOVE_REL_TOOL, delta, brk=brk)


def move_tool_z(dz: float, *, brk: bool = True) -> tuple[Command, ...]:
    """pyadept ``MoveToolZ``: along the tool's own z axis by ``dz`` mm."""
    return move_rel_tool((0.0, 0.0, dz, 0.0, 0.0, 0.0), brk=brk)


def move_joints(joints: Vector6, *, brk: bool = True) -> tuple[Command, ...]:
    return motion(Skill.MOVE_JOINTS, joints, brk=brk)


def move_rel_joints(delta: Vector6, *, brk: bool = True) -> tuple[Command, ...]:
    return motion(Skill.MOVE_REL_JOINTS, delta, brk=brk)


def set_speed(percent: float) -> Command:
    return Command(Skill.SET_SPEED, (percent,))


def monitor_speed(percent: float) -> Command:
    return Command(Skill.MONITOR_SPEED, (percent,))


BREAK = Command(Skill.BREAK)
ENABLE_AIR = Command(Skill.ENABLE_AIR)
DISABLE_AIR = Command(Skill.DISABLE_AIR)
GRIPPER_OPEN = Command(Skill.GRIPPER_OPEN)
GRIPPER_CLOSE = Command(Skill.GRIPPER_CLOSE)
MOVEHOME = Command(Skill.MOVEHOME)
