"""The RSI Ethernet configuration: Fig. 2 of the seed, the shipped default, and every way a file can be wrong."""
from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot_bridges.kuka_rsi.config import (
    MAX_CONFIG_BYTES,
    ConfigError,
    RsiRoles,
    default_config,
    default_config_path,
    load_config,
    parse_config,
)

# Fig. 2 of seed 003 (ITRA), verbatim.
FIGURE_2 = """<ROOT>
  <CONFIG>
    <IP_NUMBER>10.1.1.1</IP_NUMBER>
    <PORT>49152</PORT>
    <SENTYPE>Server</SENTYPE>
    <ONLYSEND>FALSE</ONLYSEND>
  </CONFIG>

  <SEND>
    <ELEMENTS>
      <ELEMENT TAG="DEF_RIst" TYPE="DOUBLE" INDEX="INTERNAL"/>
      <ELEMENT TAG="DEF_AIPos" TYPE="DOUBLE" INDEX="INTERNAL"/>
      <ELEMENT TAG="Digout_o1" TYPE="BOOL" INDEX="1"/>
      <ELEMENT TAG="Digout_o2" TYPE="BOOL" INDEX="2"/>
      <ELEMENT TAG="Digout_o3" TYPE="BOOL" INDEX="3"/>
      <ELEMENT TAG="Digout_o4" TYPE="BOOL" INDEX="4"/>
    </ELEMENTS>
  </SEND>

  <RECEIVE>
    <ELEMENTS>
      <ELEMENT TAG="D1" TYPE="DOUBLE" INDEX="1" HOLDON="1"/>
      <ELEMENT TAG="D2" TYPE="DOUBLE" INDEX="2" HOLDON="1"/>
      <ELEMENT TAG="D3" TYPE="DOUBLE" INDEX="3" HOLDON="1"/>
      <ELEMENT TAG="D4" TYPE="DOUBLE" INDEX="4" HOLDON="1"/>
      <ELEMENT TAG="D5" TYPE="DOUBLE" INDEX="5" HOLDON="1"/>
      <ELEMENT TAG="D6" TYPE="DOUBLE" INDEX="6" HOLDON="1"/>
      <ELEMENT TAG="D7" TYPE="DOUBLE" INDEX="7" HOLDON="1"/>
      <ELEMENT TAG="D8" TYPE="DOUBLE" INDEX="8" HOLDON="1"/>
      <ELEMENT TAG="B1" TYPE="BOOL" INDEX="9" HOLDON="1"/>
      <ELEMENT TAG="B2" TYPE="BOOL" INDEX="10" HOLDON="1"/>
      <ELEMENT TAG="B3" TYPE="BOOL" INDEX="11" HOLDON="1"/>
      <ELEMENT TAG="B4" TYPE="BOOL" INDEX="12" HOLDON="1"/>
    </ELEMENTS>
  </RECEIVE>
</ROOT>
"""


def _with(old: str, new: str) -> str:
    assert old in FIGURE_2
    return FIGURE_2.replace(old, new, 1)


def test_figure_2_of_the_seed_parses_into_its_packet_values() -> None:
    config = parse_config(FIGURE_2, "fig2.xml")
    assert (config.ip, config.port, config.sentype, config.onlysend) == ("10.1.1.1", 49152, "Server", False)
    send = [f.key for f in config.send_fields]
    assert send[:6] == ["RIst.X", "RIst.Y", "RIst.Z", "RIst.A", "RIst.B", "RIst.C"]
    assert send[6:12] == [f"AIPos.A{i}" for i in range(1, 7)]
    assert send[12:] == ["Digout_o1", "Digout_o2", "Digout_o3", "Digout_o4"]
    receive = config.receive_fields
    assert [f.key for f in receive] == [f"D{i}" for i in range(1, 9)] + ["B1", "B2", "B3", "B4"]
    assert all(f.holdon for f in receive)
    assert [f.type for f in receive[:8]] == ["DOUBLE"] * 8 and [f.type for f in receive[8:]] == ["BOOL"] * 4


def test_the_default_configuration_carries_every_role_the_bridge_uses() -> None:
    config = load_config(default_config_path())
    roles = RsiRoles()
    assert roles.handshake(config) and roles.axis(config) and roles.cartesian(config)
    assert roles.tools(config) == ("Tool.o1", "Tool.o2", "Tool.o3")
    assert config.has_send("Delay.D") and config.has_receive("Stop")
    assert default_config().sentype == config.sentype
    # Fig. 2 has the handshake flags under other names and no correction tags.
    fig2 = parse_config(FIGURE_2)
    assert not roles.axis(fig2) and not roles.cartesian(fig2) and not roles.handshake(fig2)


def test_kukas_indx_spelling_is_accepted() -> None:
    config = parse_config(_with('TAG="D1" TYPE="DOUBLE" INDEX="1"', 'TAG="D1" TYPE="DOUBLE" INDX="1"'))
    assert config.receive_fields[0].key == "D1"


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("<SENTYPE>Server</SENTYPE>", "", ["fig2.xml:2", "SENTYPE", "missing"]),
        ("<SENTYPE>Server</SENTYPE>", "<SENTYPE>Ser ver</SENTYPE>", ["fig2.xml:5", "SENTYPE"]),
        ("<PORT>49152</PORT>", "<PORT>99999</PORT>", ["fig2.xml:4", "PORT"]),
        ("<ONLYSEND>FALSE</ONLYSEND>", "<ONLYSEND>maybe</ONLYSEND>", ["fig2.xml:6", "ONLYSEND"]),
        ('TAG="D2" TYPE="DOUBLE"', 'TAG="D2" TYPE="FLOAT"', ["fig2.xml:23", "TYPE", "D2"]),
        ('TAG="D2" TYPE="DOUBLE" INDEX="2"', 'TAG="D1" TYPE="DOUBLE" INDEX="2"', ["fig2.xml:23", "D1", "line 22"]),
        ('TAG="D2" TYPE="DOUBLE" INDEX="2"', 'TAG="D2" TYPE="DOUBLE" INDEX="1"', ["fig2.xml:23", "INDEX 1", "line 22"]),
        ('TAG="D2" TYPE="DOUBLE" INDEX="2"', 'TAG="D2" TYPE="DOUBLE" INDEX="65"', ["fig2.xml:23", "INDEX"]),
        ('TAG="DEF_RIst"', 'TAG="DEF_Bogus"', ["fig2.xml:11", "DEF_Bogus", "not a SEND keyword"]),
        ('TAG="DEF_RIst" TYPE="DOUBLE" INDEX="INTERNAL"', 'TAG="DEF_RIst" TYPE="DOUBLE" INDEX="3"', ["fig2.xml:11", "INTERNAL"]),
        ('TAG="DEF_AIPos" TYPE="DOUBLE"', 'TAG="DEF_AIPos" TYPE="LONG"', ["fig2.xml:12", "DOUBLE"]),
        ('TAG="Digout_o1" TYPE="BOOL" INDEX="1"/>', 'TAG="Digout_o1" TYPE="BOOL" INDEX="1" HOLDON="1"/>', ["fig2.xml:13", "HOLDON"]),
        ('TAG="B1" TYPE="BOOL" INDEX="9" HOLDON="1"', 'TAG="B1" TYPE="BOOL" INDEX="9" HOLDON="2"', ["fig2.xml:30", "HOLDON"]),
        ('TAG="B1"', 'TAG="IPOC"', ["fig2.xml:30", "IPOC"]),
        ('TAG="B1"', 'TAG="B-1"', ["fig2.xml:30", "TAG"]),
        ("<ELEMENTS>\n      <ELEMENT TAG=\"D1\"", "<ELEMENTS>\n      <BOGUS/><ELEMENT TAG=\"D1\"", ["fig2.xml:22", "BOGUS"]),
        ("</ROOT>", "", ["fig2.xml", "not well-formed"]),
        ("<ROOT>", "<!DOCTYPE r [<!ENTITY x 'y'>]><ROOT>", ["fig2.xml:1", "DOCTYPE"]),
    ],
)
def test_a_wrong_file_is_refused_naming_file_line_and_field(old: str, new: str, words: list[str]) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(FIGURE_2.replace(old, new, 1), "fig2.xml")
    for word in words:
        assert word in str(caught.value)


def test_an_element_cannot_be_both_a_value_and_have_attributes() -> None:
    text = _with('TAG="D2"', 'TAG="D1.x"')
    with pytest.raises(ConfigError, match="D1"):
        parse_config(text, "fig2.xml")


def test_oversized_files_are_refused_before_parsing(tmp_path) -> None:  # type: ignore[no-untyped-def]
    big = FIGURE_2.replace("</ROOT>", "<!--" + "x" * MAX_CONFIG_BYTES + "--></ROOT>")
    with pytest.raises(ConfigError, match="more than"):
        parse_config(big, "big.xml")
    path = tmp_path / "big.xml"
    path.write_text(big)
    with pytest.raises(ConfigError, match="big.xml"):
        load_config(path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.xml")


@given(st.integers(min_value=0, max_value=len(FIGURE_2)), st.binary(max_size=40))
def test_truncated_or_corrupted_files_raise_config_error_only(cut: int, noise: bytes) -> None:
    data = FIGURE_2.encode()[:cut] + noise
    try:
        parse_config(data, "fuzz.xml")
    except ConfigError as error:
        assert "fuzz.xml" in str(error)
