"""The AdeptServer wire format: bytes exactly as the seed and pyadept write them, and hardened parsing."""
from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot_bridges.vplus import codec
from robot_bridges.vplus.codec import (
    Ack,
    Command,
    DecodeError,
    FrameError,
    LineSplitter,
    Message,
    Skill,
    UnknownSkill,
    decode_ack,
    decode_message,
    encode_messages,
)

SEED_CHAIN = b"eae86869:move_to:-80.000,-481.000,112.500,180.000,90.000,180.000\r\nnee861124:break\r\n"
SEED_ACK = b"eae86869:done:2492.516,2492.539:480.014,-0.038,709.975,0.000,179.995,0.004"


def test_the_seed_command_chain_is_reproduced_byte_for_byte() -> None:
    move, brk = codec.move_to((-80, -481, 112.5, 180, 90, 180))
    assert encode_messages([Message("eae86869", move), Message("nee861124", brk)]) == SEED_CHAIN


@pytest.mark.parametrize(
    ("command", "expected"),
    [
        (Command(Skill.MOVE_TO, (-80, -481, 112.5, 180, 90, 180)), b"move_to:-80.000,-481.000,112.500,180.000,90.000,180.000"),
        (Command(Skill.MOVE_REL_WORLD, (0, 0, -2.5, 0, 0, 0)), b"move_rel_world:0.000,0.000,-2.500,0.000,0.000,0.000"),
        # init_move of the seed's ufloop: MoveRelTool([40, -25, 185, 0, 0, 0])
        (Command(Skill.MOVE_REL_TOOL, (40, -25, 185, 0, 0, 0)), b"move_rel_tool:40.000,-25.000,185.000,0.000,0.000,0.000"),
        (Command(Skill.MOVE_JOINTS, (0, -90, 180, 0, 90, 0)), b"move_joints:0.000,-90.000,180.000,0.000,90.000,0.000"),
        (Command(Skill.MOVE_REL_JOINTS, (-90, 60, 30, -90, 0, 0)), b"move_rel_joints:-90.000,60.000,30.000,-90.000,0.000,0.000"),
        (codec.BREAK, b"break"),
        (codec.set_speed(50), b"set_speed:50"),
        (codec.set_speed(0.5), b"set_speed:0.500"),
        (codec.ENABLE_AIR, b"enable_air"),
        (codec.DISABLE_AIR, b"disable_air"),
        (codec.GRIPPER_OPEN, b"gripper_open"),
        (codec.GRIPPER_CLOSE, b"gripper_close"),
        (codec.MOVEHOME, b"movehome"),
    ],
)
def test_every_skill_encodes_in_the_seed_format(command: Command, expected: bytes) -> None:
    message = Message("0a1b2c3d", command)
    assert message.encode() == b"0a1b2c3d:" + expected + b"\r\n"
    assert decode_message(message.encode()[:-2]) == message


def test_every_skill_of_the_server_is_covered_by_a_builder() -> None:
    built = {
        *codec.move_to((0,) * 6),
        *codec.move_rel_world((0,) * 6),
        *codec.move_rel_tool((0,) * 6),
        *codec.move_joints((0,) * 6),
        *codec.move_rel_joints((0,) * 6),
        codec.set_speed(10),
        codec.monitor_speed(10),
        codec.ENABLE_AIR,
        codec.DISABLE_AIR,
        codec.GRIPPER_OPEN,
        codec.GRIPPER_CLOSE,
        codec.MOVEHOME,
    }
    assert {c.skill for c in built} == set(Skill)


def test_motion_is_followed_by_break_unless_asked_not_to() -> None:
    assert codec.move_tool_z(1.5) == (Command(Skill.MOVE_REL_TOOL, (0, 0, 1.5, 0, 0, 0)), codec.BREAK)
    assert codec.move_tool_z(1.5, brk=False) == (Command(Skill.MOVE_REL_TOOL, (0, 0, 1.5, 0, 0, 0)),)


def test_negative_zero_and_rounding_are_written_as_pyadept_would() -> None:
    assert codec.format_number(-0.0001) == "0.000"
    assert codec.format_number(1.23456) == "1.235"
    assert codec.format_number(-481) == "-481.000"


# ---------------------------------------------------------------------------------- ids
def test_generated_ids_follow_pyadept_first_8_chars_of_a_uuid4() -> None:
    ids = {codec.new_id() for _ in range(500)}
    assert all(re.fullmatch(r"[0-9a-f]{8}", i) for i in ids)
    assert len(ids) > 490  # random, not a counter


def test_ids_are_opaque_tokens_the_seeds_nine_character_id_included() -> None:
    assert Message("nee861124", codec.BREAK).encode() == b"nee861124:break\r\n"
    assert decode_message(b"nee861124:break").id == "nee861124"
    assert decode_ack(b"X1:done:0.000,0.001:0.000,0.000,0.000,0.000,0.000,0.000").id == "X1"


@pytest.mark.parametrize("bad", ["", "a:b", "ab cd", "a\r\n", "0123456789abcdefX", "é1234567", "-1"])
def test_ids_that_could_break_framing_are_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="message id"):
        Message(bad, codec.BREAK)


# -------------------------------------------------------------------------------- acks
def test_the_seed_ack_is_parsed() -> None:
    ack = decode_ack(SEED_ACK)
    assert ack == Ack("eae86869", 2492.516, 2492.539, (480.014, -0.038, 709.975, 0.0, 179.995, 0.004))
    assert ack.encode() == SEED_ACK + b"\r\n"


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"eae86869:done:2492.516:480.014,-0.038,709.975,0.000,179.995,0.004", "expected 2"),
        (b"eae86869:done:1.000,2.000:480.014,-0.038,709.975,0.000,179.995", "expected 6"),
        (b"eae86869:done:1.000,2.000:480.014,abc,709.975,0.000,179.995,0.004", "not a decimal"),
        (b"eae86869:done:1.000,2.000", "expected <id>"),
        (b"eae86869:DONE!:1.000,2.000:1,2,3,4,5,6", "bad status"),
        (b"ea:e86869:done:1.000,2.000:1,2,3,4,5,6", "expected <id>"),
        (b"eae86869:done:1.000,2.000:1,2,3,4,5,6\x00", "control characters"),
        (b"eae86869:done:1.000,2.000:1,2,3,4,5,\xff", "non-ASCII"),
        (b"eae86869:done:nan,2.000:1,2,3,4,5,6", "not a decimal"),
        (b"x" * 300, "exceeds"),
    ],
)
def test_malformed_acks_are_rejected_with_a_reason(line: bytes, reason: str) -> None:
    with pytest.raises(DecodeError, match=reason) as caught:
        decode_ack(line)
    assert caught.value.line == line


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"break", "expected <id>"),
        (b"a1:move_to:1,2,3", "expected 6"),
        (b"a1:move_to", "needs 6"),
        (b"a1:break:1", "takes no arguments"),
        (b"a1:set_speed:0", "percentage"),
        (b"a1:set_speed:101", "percentage"),
        (b"a1:move_to:1,2,3,4,5,1e3", "not a decimal"),
        (b"a 1:break", "bad message id"),
        (b"a1:move_to:1,2,3,4,5,6:7", "expected <id>"),
    ],
)
def test_malformed_commands_are_rejected_with_a_reason(line: bytes, reason: str) -> None:
    with pytest.raises(DecodeError, match=reason):
        decode_message(line)


def test_an_unknown_skill_is_told_apart_from_garbage() -> None:
    with pytest.raises(UnknownSkill) as caught:
        decode_message(b"c0ffee00:fly_to_moon:1.000")
    assert (caught.value.msg_id, caught.value.skill) == ("c0ffee00", "fly_to_moon")


@pytest.mark.parametrize(
    ("skill", "args", "match"),
    [
        (Skill.MOVE_TO, (1, 2, 3), "takes 6"),
        (Skill.BREAK, (1,), "takes 0"),
        (Skill.MOVE_JOINTS, (0, 0, 0, 0, 0, float("nan")), "finite"),
        (Skill.MOVE_JOINTS, (0, 0, 0, 0, 0, 2e6), "magnitude"),
        (Skill.SET_SPEED, (0,), "percentage"),
    ],
)
def test_invalid_commands_cannot_be_built(skill: Skill, args: tuple[float, ...], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Command(skill, args)


# ----------------------------------------------------------------------------- framing
def test_lines_are_reassembled_at_every_byte_boundary() -> None:
    expected = [SEED_CHAIN.split(b"\r\n")[0], b"nee861124:break"]
    for cut in range(len(SEED_CHAIN) + 1):
        splitter = LineSplitter()
        assert splitter.feed(SEED_CHAIN[:cut]) + splitter.feed(SEED_CHAIN[cut:]) == expected
        assert splitter.pending == b""


def test_lines_are_reassembled_one_byte_at_a_time() -> None:
    splitter = LineSplitter()
    lines = [line for b in SEED_CHAIN for line in splitter.feed(bytes([b]))]
    assert [decode_message(line).command.skill for line in lines] == [Skill.MOVE_TO, Skill.BREAK]


@given(st.lists(st.integers(min_value=0, max_value=len(SEED_CHAIN) * 3), max_size=12))
def test_any_segmentation_of_a_stream_gives_the_same_lines(cuts: list[int]) -> None:
    stream = SEED_CHAIN + SEED_ACK + b"\r\n" + SEED_CHAIN
    points = sorted({0, len(stream), *(c % (len(stream) + 1) for c in cuts)})
    splitter = LineSplitter()
    lines = [line for a, b in zip(points, points[1:]) for line in splitter.feed(stream[a:b])]
    assert lines == [line for line in stream.split(b"\r\n") if line]


def test_an_endless_line_is_a_frame_error_and_the_buffer_is_dropped() -> None:
    splitter = LineSplitter(max_line=64)
    splitter.feed(b"a" * 60)
    with pytest.raises(FrameError, match="no delimiter within 64 bytes"):
        splitter.feed(b"a" * 10)
    assert splitter.pending == b""


def test_empty_lines_are_skipped() -> None:
    assert LineSplitter().feed(b"\r\n\r\na1:break\r\n\r\n") == [b"a1:break"]


# -------------------------------------------------------------------- property tests
numbers = st.floats(min_value=-99999, max_value=99999, allow_nan=False)
vectors = st.tuples(numbers, numbers, numbers, numbers, numbers, numbers)
motion_skills = st.sampled_from(sorted(codec.MOTION_SKILLS, key=lambda s: s.value))


@given(motion_skills, vectors, st.from_regex(r"[0-9A-Za-z]{1,16}", fullmatch=True))
def test_motion_messages_round_trip_to_three_decimals(skill: Skill, values: tuple[float, ...], msg_id: str) -> None:
    message = Message(msg_id, Command(skill, values))
    decoded = decode_message(message.encode()[:-2])
    assert decoded.id == msg_id and decoded.command.skill is skill
    assert all(abs(a - b) <= 0.0005 + 1e-9 for a, b in zip(decoded.command.args, values))


@given(st.binary(max_size=300))
def test_random_bytes_never_escape_as_anything_but_decode_error(data: bytes) -> None:
    for decode in (decode_message, decode_ack):
        try:
            decode(data)
        except DecodeError:
            pass


@given(st.integers(min_value=0, max_value=SEED_ACK.rindex(b",")))
def test_truncated_acks_are_rejected(cut: int) -> None:
    with pytest.raises(DecodeError):
        decode_ack(SEED_ACK[:cut])


@given(st.integers(min_value=0, max_value=len(SEED_CHAIN) - 4))
def test_truncated_commands_decode_cleanly_or_are_rejected(cut: int) -> None:
    line = SEED_CHAIN.split(b"\r\n")[0][:cut]
    try:
        message = decode_message(line)
    except DecodeError:
        return
    assert message.command.skill is Skill.MOVE_TO  # a cut inside the last number is still a number


ack_numbers = st.floats(min_value=-99999, max_value=99999, allow_nan=False)


@given(st.from_regex(r"[0-9A-Za-z]{1,16}", fullmatch=True), st.floats(0, 1e6), st.floats(0, 1e6), st.tuples(*[ack_numbers] * 6))
def test_the_fast_ack_parser_agrees_with_the_field_by_field_one(msg_id: str, t1: float, t2: float, pose: tuple[float, ...]) -> None:
    line = Ack(msg_id, t1, t2, pose).encode()[:-2]  # type: ignore[arg-type]
    assert decode_ack(line) == codec.decode_ack_by_fields(line)


_numbers = st.one_of(
    st.sampled_from([0.0, -0.0, -0.0004, 0.0004, -0.0005, 0.0005, -0.00049999, 999999.9994, -999999.9994]),
    st.floats(min_value=-999_999.0, max_value=999_999.0, allow_nan=False),
)


@given(st.from_regex(r"[0-9A-Za-z]{1,16}", fullmatch=True), st.tuples(*[_numbers] * 6), st.tuples(_numbers, _numbers))
def test_an_ack_writes_every_number_as_format_number_does_and_reads_back(msg_id: str, pose: tuple[float, ...], times: tuple[float, float]) -> None:
    """The ack is written in one formatting now: each number must still read as pyadept writes it
    (three decimals, never '-0.000'), and decode to what the writer meant."""
    t_recv, t_done = (abs(t) for t in times)
    ack = codec.Ack(msg_id, t_recv, t_done, pose)  # type: ignore[arg-type]
    numbers = [codec.format_number(t_recv, codec.MAX_TIMESTAMP), codec.format_number(t_done, codec.MAX_TIMESTAMP)]
    expected = f"{msg_id}:done:{numbers[0]},{numbers[1]}:{','.join(codec.format_number(v) for v in pose)}\r\n".encode()
    assert ack.encode() == expected
    assert codec.decode_ack(expected[:-2]) == codec.Ack(msg_id, float(numbers[0]), float(numbers[1]), tuple(float(codec.format_number(v)) for v in pose))  # type: ignore[arg-type]


@pytest.mark.parametrize(("bad_value", "bad_time"), [(float("nan"), float("nan")), (float("inf"), -float("inf")), (1e6, 1e8), (-1e6, -1e8)])
def test_an_ack_with_a_number_out_of_bounds_is_not_written(bad_value: float, bad_time: float) -> None:
    with pytest.raises(ValueError):
        codec.Ack("ab12", 0.0, 0.0, (0.0, bad_value, 0.0, 0.0, 0.0, 0.0)).encode()
    with pytest.raises(ValueError):
        codec.Ack("ab12", 0.0, bad_time, (0.0,) * 6).encode()  # type: ignore[arg-type]


def test_a_command_read_again_is_the_same_and_a_refused_one_is_refused_every_time() -> None:
    """The server keeps the commands it decoded, by their text: the same line gives an equal
    message with its own id; a line it refused is refused again (nothing refused is kept)."""
    first = codec.decode_message(b"0a1b2c3d:set_speed:50")
    again = codec.decode_message(b"ffff0000:set_speed:50")
    assert again == Message("ffff0000", first.command) and again.command == codec.set_speed(50)
    for _ in range(2):
        with pytest.raises(codec.DecodeError, match="set_speed takes a percentage"):
            codec.decode_message(b"0a1b2c3d:set_speed:150")
    assert codec.decode_message(b"0a1b2c3d:move_to:1,2,3,4,5,6").command.args == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
