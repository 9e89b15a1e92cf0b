"""RSI Ethernet configurations in the layouts other projects ship, written here for the tests.

The layouts (which SEND and RECEIVE elements, their TYPE, INDX, HOLDON) are those of kroshu's
kuka_drivers / kuka-external-control-sdk (KSS and iiQKA.OS2, plain and with GPIO; an earlier KSS one
that sends RIst, AIPos and Delay only) and of ROS-Industrial's kuka_experimental (KR C4 and KR C2, whose
comments name the DEF_Tech keywords).  Their files are not copied: each text below is built from the
element lists, with this project's loopback address.
"""
from __future__ import annotations

_AXES = tuple(f"A{i}" for i in range(1, 7))


def _config(sentype: str, port: int, send: list[str], receive: list[str], extra_config: str = "", extra_attributes: str = "") -> str:
    """A configuration file's text; ``send``/``receive`` hold ``TAG TYPE INDX [HOLDON]`` lines."""

    def element(line: str, holdon_allowed: bool) -> str:
        tag, vtype, index, *holdon = line.split()
        hold = f' HOLDON="{holdon[0]}"' if holdon and holdon_allowed else ""
        return f'      <ELEMENT TAG="{tag}" TYPE="{vtype}" INDX="{index}"{extra_attributes}{hold} />'

    return "\n".join(
        [
            "<ROOT>",
            "  <CONFIG>",
            "    <IP_NUMBER>127.0.0.1</IP_NUMBER>  <!-- the external system -->",
            f"    <PORT>{port}</PORT>",
            *([extra_config] if extra_config else []),
            f"    <SENTYPE>{sentype}</SENTYPE>",
            "    <ONLYSEND>FALSE</ONLYSEND>",
            "  </CONFIG>",
            "  <SEND>",
            "    <ELEMENTS>",
            *(element(line, False) for line in send),
            "    </ELEMENTS>",
            "  </SEND>",
            "  <RECEIVE>",
            "    <ELEMENTS>",
            *(element(line, True) for line in receive),
            "    </ELEMENTS>",
            "  </RECEIVE>",
            "</ROOT>",
            "",
        ]
    )


_KROSHU_SEND = ["DEF_RIst DOUBLE INTERNAL", "DEF_AIPos DOUBLE INTERNAL", "DEF_EIPos DOUBLE INTERNAL", "DEF_Delay LONG INTERNAL"]
_KROSHU_RECEIVE = ["Stop BOOL 1 0", *(f"AK.{a} DOUBLE {i + 2} 1" for i, a in enumerate(_AXES))]

#: kroshu's KSS configuration: no RSol, no ASPos; Stop first, then the axis corrections.
KSS = _config("KROSHU", 59152, _KROSHU_SEND, _KROSHU_RECEIVE)
#: kroshu's iiQKA.OS2 configuration (the same elements as KSS).
IIQKA = _config("KROSHU", 59152, _KROSHU_SEND, _KROSHU_RECEIVE)
#: An earlier KSS configuration of kroshu's: RIst, AIPos and Delay only; the axis corrections first, Stop last.
KSS_EARLIER = _config(
    "KROSHU", 59152, ["DEF_RIst DOUBLE INTERNAL", "DEF_AIPos DOUBLE INTERNAL", "DEF_Delay LONG INTERNAL"],
    [*(f"AK.{a} DOUBLE {i + 1} 1" for i, a in enumerate(_AXES)), "Stop BOOL 7 0"],
)
#: kroshu's GPIO configuration: inputs GPIO.01 and GPIO.02 in SEND, output GPIO.01 in RECEIVE.
GPIO = _config(
    "KROSHU", 59152, [*_KROSHU_SEND, "GPIO.01 BOOL 1", "GPIO.02 BOOL 2"], [*_KROSHU_RECEIVE, "GPIO.01 BOOL 8 1"],
)
_ROS_I_SEND = ["DEF_RIst DOUBLE INTERNAL", "DEF_RSol DOUBLE INTERNAL", "DEF_AIPos DOUBLE INTERNAL", "DEF_ASPos DOUBLE INTERNAL", "DEF_Delay LONG INTERNAL"]
_ROS_I_RECEIVE = [f"AK.{a} DOUBLE {i + 1} 1" for i, a in enumerate(_AXES)]
#: ROS-Industrial's KR C4 configuration (kuka_rsi_hw_interface): the four reports and Delay; AK only.
ROS_I_KR_C4 = _config("ImFree", 49152, _ROS_I_SEND, _ROS_I_RECEIVE)
#: ROS-Industrial's KR C2 configuration: a PROTOCOL in CONFIG and a UNIT on every element, which RSI reads and we need not.
ROS_I_KR_C2 = _config("ImFree", 49152, _ROS_I_SEND, _ROS_I_RECEIVE, "    <PROTOCOL>UDP</PROTOCOL>", ' UNIT="0"')
#: kroshu's configuration for one external axis: its correction EK.E1 after the robot's.
EXTERNAL_AXIS = _config("KROSHU", 59152, _KROSHU_SEND, [*_KROSHU_RECEIVE, "EK.E1 DOUBLE 8 1"])
#: The technology parameters ROS-I's KR C4 file names in its comments: generator 1 (advance run) in
#: SEND, generator 2 (main run) in RECEIVE, with the KSS GPIO elements beside them.
TECH = _config(
    "KROSHU", 59152, [*_KROSHU_SEND, "GPIO.01 BOOL 1", "DEF_Tech.C1 DOUBLE INTERNAL", "DEF_Tech.T1 DOUBLE INTERNAL"],
    [*_KROSHU_RECEIVE, "GPIO.01 BOOL 8 1", "DEF_Tech.T2 DOUBLE INTERNAL 0"],
)

#: Every layout by name.
ALL = {
    "kss": KSS, "iiqka": IIQKA, "kss_earlier": KSS_EARLIER, "gpio": GPIO, "external_axis": EXTERNAL_AXIS, "ros_i_kr_c4": ROS_I_KR_C4,
    "ros_i_kr_c2": ROS_I_KR_C2, "tech": TECH,
}

#: An application a configuration without Cartesian corrections or tool outputs can run: joint moves,
#: point-to-point moves to cell frames, a recorded sweep streamed point by point, a dwell, home.
JOINT_ONLY_APP = """<?xml version="1.0" encoding="UTF-8"?>
<application name="rsi_joint_only" robot="kuka" cell="{cell}">
  <error_policy retries="0" action="abort"/>
  <operation id="1" name="ready"><arm><function name="move_joints"><params><param value="0 -80 85 0 35 0 deg"/></params></function></arm></operation>
  <operation id="2" name="over the tray"><arm><function name="move_to"><params><param value="part_slot"/></params></function></arm></operation>
  <operation id="3" name="record"><arm><function name="record_trajectory"><params><param value="sweep"/><param value="sweep_start sweep_end"/><param value="ptp"/><param value="true"/></params></function></arm></operation>
  <operation id="4" name="stream"><arm><function name="execute_trajectory"><params><param value="sweep"/></params></function></arm></operation>
  <operation id="5" name="hold"><arm><function name="wait"><params><param value="0.2"/></params></function></arm></operation>
  <operation id="6" name="home"><arm><function name="move_to_joint_pose"><params><param value="home"/></params></function></arm></operation>
</application>
"""
