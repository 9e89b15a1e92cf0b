"""<Rob> and <Sen> packets: what the configuration says travels, and nothing a hostile datagram can do."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot_bridges.kuka_rsi.codec import MAX_PACKET_BYTES, REASONS, PacketCodec, PacketError
from robot_bridges.kuka_rsi.config import default_config, parse_config
from test_rsi_config import FIGURE_2

CONFIG = default_config()
ROB = PacketCodec.rob(CONFIG)
SEN = PacketCodec.sen(CONFIG)

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


def _value(field_type: str):  # type: ignore[no-untyped-def]
    return {"DOUBLE": finite, "LONG": st.integers(-(2**31), 2**31), "BOOL": st.booleans(), "STRING": st.text(max_size=20)}[field_type]


rob_values = st.tuples(*[_value(f.type) for f in ROB.fields])


@given(rob_values, st.integers(min_value=0, max_value=2**63 - 1))
def test_a_rob_packet_round_trips_every_configured_value(values: tuple, ipoc: int) -> None:  # type: ignore[type-arg]
    packet = ROB.encode(list(values), ipoc)
    out = list(ROB.defaults)
    assert ROB.decode_into(packet, out) == ipoc
    for field, sent, got in zip(ROB.fields, values, out):
        if field.type == "DOUBLE":
            assert got == pytest.approx(sent, abs=1e-6)
        else:
            assert got == sent


def test_packets_look_like_rsi_packets() -> None:
    values = dict.fromkeys(SEN.keys, 0.0)
    values.update({"AK.A1": 1.5, "B2": True, "Stop": False, "Tool.o1": True})
    packet = SEN.encode_map(values, 4242)
    assert packet.startswith(b'<Sen Type="DualArmExecutive"><AK A1="1.500000" A2="0.000000"')
    assert b"<B2>1</B2>" in packet and b'<Tool o1="1" o2="0" o3="0"/>' in packet
    assert packet.endswith(b"<IPOC>4242</IPOC></Sen>")
    ipoc, decoded = SEN.decode(packet)
    assert ipoc == 4242 and decoded["AK.A1"] == 1.5 and decoded["B2"] is True


def test_figure_2_packets_carry_text_elements() -> None:
    fig2 = parse_config(FIGURE_2)
    sen = PacketCodec.sen(fig2)
    packet = sen.encode_map({"D1": 10.0, "D7": 2.0, "B3": True}, 7)
    assert b'<Sen Type="Server"><D1>10.000000</D1>' in packet and b"<B3>1</B3>" in packet
    rob = PacketCodec.rob(fig2)
    text = (
        b'<Rob Type="KUKA"><RIst X="1" Y="2" Z="3" A="4" B="5" C="6"/><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6"/>'
        b"<Digout_o1>1</Digout_o1><Digout_o2>0</Digout_o2><Digout_o3>TRUE</Digout_o3><Digout_o4>false</Digout_o4>"
        b"<IPOC>123645634563</IPOC></Rob>"
    )
    ipoc, values = rob.decode(text)
    assert ipoc == 123645634563 and values["RIst.Z"] == 3.0 and values["Digout_o3"] is True and values["Digout_o4"] is False


def test_elements_the_configuration_does_not_use_are_ignored() -> None:
    packet = ROB.encode(list(ROB.defaults), 5).replace(b"<IPOC>", b'<Tech C1="3"/><IPOC>')
    assert ROB.decode(packet)[0] == 5


def test_strings_are_escaped() -> None:
    config = parse_config(FIGURE_2.replace('<ELEMENT TAG="B4"', '<ELEMENT TAG="DEF_EStr" TYPE="STRING" INDEX="INTERNAL"/><ELEMENT TAG="B4"'))
    sen = PacketCodec.sen(config)
    packet = sen.encode_map({"EStr": "a<b & c"}, 1)
    assert b"<EStr>a&lt;b &amp; c</EStr>" in packet
    assert sen.decode(packet)[1]["EStr"] == "a<b & c"


GOOD = ROB.encode(list(ROB.defaults), 99)


@pytest.mark.parametrize(
    ("packet", "words"),
    [
        (GOOD.replace(b"<Rob", b"<Bob").replace(b"</Rob>", b"</Bob>"), "<Bob>"),
        (GOOD.replace(b'Type="KUKA"', b'Type="Other"'), "Type"),
        (SEN.encode(list(SEN.defaults), 1).replace(b"DualArmExecutive", b"Server"), "Type='Server'"),
        (GOOD.replace(b"<IPOC>99</IPOC>", b""), "IPOC is missing"),
        (GOOD.replace(b"<IPOC>99</IPOC>", b"<IPOC>-3</IPOC>"), "IPOC"),
        (GOOD.replace(b"<IPOC>99</IPOC>", b"<IPOC>9_9</IPOC>"), "IPOC"),
        (GOOD.replace(b"<IPOC>99</IPOC>", b"<IPOC>99</IPOC><IPOC>99</IPOC>"), "twice"),
        (GOOD.replace(b' X="0.000000"', b' X="nan"', 1), "RIst.X"),
        (GOOD.replace(b' X="0.000000"', b' X="1e999"', 1), "RIst.X"),
        (GOOD.replace(b' X="0.000000"', b' X="1_0"', 1), "RIst.X"),
        (GOOD.replace(b' X="0.000000"', b"", 1), "RIst.X is missing"),
        (GOOD.replace(b'<Delay D="0"/>', b""), "Delay.D"),
        (GOOD.replace(b'<Delay D="0"/>', b'<Delay D="x"/>'), "Delay.D"),
        (GOOD.replace(b'o1="0"', b'o1="yes"', 1), "Digout.o1"),
        (GOOD.replace(b"<RSol", GOOD[GOOD.index(b"<RIst") : GOOD.index(b"<RSol")] + b"<RSol"), "twice"),
        (b'<?xml version="1.0"?>' + GOOD, "processing instructions"),
        (b'<!DOCTYPE Rob [<!ENTITY a "aaaa">]>' + GOOD.replace(b"KUKA", b"&a;"), "DTD"),
        (GOOD[:-7], "well-formed"),
        (b"", "well-formed"),
        (GOOD + b" " * MAX_PACKET_BYTES, "exceeds"),
    ],
)
def test_bad_packets_raise_packet_error_and_change_nothing(packet: bytes, words: str) -> None:
    codec = SEN if packet.startswith(b"<Sen") else ROB
    out = ["untouched"] * len(codec.fields)
    with pytest.raises(PacketError) as caught:
        codec.decode_into(packet, out)  # type: ignore[arg-type]
    assert words in str(caught.value)
    assert out == ["untouched"] * len(codec.fields)


@given(st.binary(max_size=600))
def test_random_datagrams_raise_packet_error_only(data: bytes) -> None:
    out = list(ROB.defaults)
    try:
        ROB.decode_into(data, out)
    except PacketError:
        assert out == list(ROB.defaults)


@given(st.integers(min_value=0, max_value=len(GOOD) - 1), st.binary(max_size=8))
def test_truncated_or_spliced_packets_raise_packet_error_only(cut: int, tail: bytes) -> None:
    out = list(ROB.defaults)
    try:
        ipoc = ROB.decode_into(GOOD[:cut] + tail, out)
    except PacketError:
        return
    assert ipoc == 99 and all(not isinstance(v, float) or math.isfinite(v) for v in out)


def test_the_fast_path_and_the_full_parser_agree() -> None:
    """A packet in another but equivalent layout (attribute order, spacing, a comment) decodes the same."""
    values = list(ROB.defaults)
    values[0], values[12], values[25] = 525.25, -90.5, True
    packet = ROB.encode(values, 1234)
    rearranged = packet.replace(b'<RIst X="525.250000" Y="0.000000"', b'<RIst  Y="0.000000" X="525.250000"').replace(
        b"<IPOC>", b"<!-- a comment --><IPOC>"
    )
    fast, slow = list(ROB.defaults), list(ROB.defaults)
    assert ROB.decode_into(packet, fast) == 1234
    with pytest.raises(PacketError, match="declarations"):
        ROB.decode_into(rearranged, slow)  # comments are refused outright: no controller sends them
    assert ROB.decode_into(rearranged.replace(b"<!-- a comment -->", b"\n  "), slow) == 1234
    assert fast == slow


# ------------------------------------------------------------------- how peers actually vary
ROS_I_CONFIG = parse_config(
    """<ROOT><CONFIG><IP_NUMBER>127.0.0.1</IP_NUMBER><PORT>49152</PORT><SENTYPE>ImFree</SENTYPE><ONLYSEND>FALSE</ONLYSEND></CONFIG>
    <SEND><ELEMENTS>
      <ELEMENT TAG="DEF_RIst" TYPE="DOUBLE" INDX="INTERNAL"/><ELEMENT TAG="DEF_RSol" TYPE="DOUBLE" INDX="INTERNAL"/>
      <ELEMENT TAG="DEF_AIPos" TYPE="DOUBLE" INDX="INTERNAL"/><ELEMENT TAG="DEF_ASPos" TYPE="DOUBLE" INDX="INTERNAL"/>
      <ELEMENT TAG="DEF_Delay" TYPE="LONG" INDX="INTERNAL"/>
    </ELEMENTS></SEND>
    <RECEIVE><ELEMENTS>"""
    + "".join(f'<ELEMENT TAG="AK.A{i}" TYPE="DOUBLE" INDX="{i}" HOLDON="1"/>' for i in range(1, 7))
    + "</ELEMENTS></RECEIVE></ROOT>",
    "ros_i_like.xml",
)


def _element_tree_packet(root_attribute: str, sort: bool) -> bytes:
    """A <Rob> packet as Python's ElementTree writes it (ROS-I's simulator): str() of floats, and
    under Python 2 the attributes sorted by name."""
    def element(parent: ET.Element, tag: str, attributes: dict[str, str]) -> None:
        ET.SubElement(parent, tag, dict(sorted(attributes.items())) if sort else attributes)

    root = ET.Element("Rob", {root_attribute: "KUKA"})
    for tag in ("RIst", "RSol"):
        element(root, tag, {k: "0.0" for k in "XYZABC"})
    element(root, "AIPos", {f"A{i}": str(v) for i, v in enumerate((0.0, -90.0, 90.0, 0.0, 90.0, 1e-05), start=1)})
    element(root, "ASPos", {f"A{i}": str(v) for i, v in enumerate((0.0, -90.0, 90.0, 0.0, 90.0, 0.0), start=1)})
    element(root, "Delay", {"D": "0"})
    ET.SubElement(root, "IPOC").text = "17"
    return ET.tostring(root)


@pytest.mark.parametrize("sort", [False, True])
def test_packets_as_ros_industrials_simulator_writes_them_are_read(sort: bool) -> None:
    rob = PacketCodec.rob(ROS_I_CONFIG)
    ipoc, values = rob.decode(_element_tree_packet("TYPE", sort))
    assert ipoc == 17 and values["AIPos.A5"] == 90.0 and values["AIPos.A6"] == 1e-05 and values["Delay.D"] == 0


def test_attribute_names_match_whatever_their_case() -> None:
    packet = GOOD.replace(b"Type=", b"TYPE=").replace(b" A1=", b" a1=").replace(b" X=", b" x=")
    out = list(ROB.defaults)
    assert ROB.decode_into(packet, out) == 99
    assert ROB.decode_into(GOOD.replace(b"Type=", b"type="), out) == 99


@pytest.mark.parametrize(
    ("packet", "reason", "words"),
    [
        (GOOD.replace(b"Type=", b"Kind="), "root attribute", "<Rob> has no Type attribute (its attributes: Kind)"),
        (GOOD.replace(b'"KUKA"', b'"kuka"'), "root type", "<Rob Type='kuka'> where 'KUKA' is configured"),
        (GOOD.replace(b' A1="0.000000"', b' A1="0.000000" a1="1.0"', 1), "duplicate", "gives attribute a1 twice"),
        (GOOD.replace(b"<Rob", b"<Bob").replace(b"</Rob>", b"</Bob>"), "root element", "<Bob>"),
        (GOOD.replace(b'<Delay D="0"/>', b""), "missing", "Delay.D"),
        (GOOD.replace(b' X="0.000000"', b' X="nan"', 1), "value", "RIst.X"),
        (GOOD.replace(b"<IPOC>99</IPOC>", b"<IPOC>x</IPOC>"), "ipoc", "IPOC"),
        (b"\x00\x01garbage", "xml", "well-formed"),
        (b'<?xml version="1.0"?>' + GOOD, "markup", "processing instructions"),
        (GOOD + b" " * MAX_PACKET_BYTES, "size", "exceeds"),
    ],
)
def test_every_refusal_names_its_reason(packet: bytes, reason: str, words: str) -> None:
    with pytest.raises(PacketError) as caught:
        ROB.decode(packet)
    assert caught.value.reason == reason and reason in REASONS and words in str(caught.value)
