"""Support for the application-model tests: a small catalog, sample files, and position helpers.

The tests need functions of every kind the validator treats specially (cell references, joint
poses, full-body and master/slave synchronisation, hand holds) without depending on the app
function libraries, so the model can be tested on its own.  Expected positions are computed from
the test's own text (``at``), independently of how the loader finds them.
"""
from __future__ import annotations

from pathlib import Path

from core_functions.catalog import Catalog, Hold, ParamSpec, ParamType, skill


def pos(text: str, needle: str, occurrence: int = 1) -> tuple[int, int]:
    """1-based line and column of the n-th ``needle`` in ``text``."""
    index = -1
    for _ in range(occurrence):
        index = text.index(needle, index + 1)
    return text.count("\n", 0, index) + 1, index - (text.rfind("\n", 0, index) + 1) + 1


def at(path: Path, text: str, needle: str, message: str, occurrence: int = 1) -> str:
    """The diagnostic ``FILE:LINE:COL: message`` expected at the n-th ``needle``."""
    line, col = pos(text, needle, occurrence)
    return f"{path}:{line}:{col}: {message}"


class Core:
    @skill(groups=("arm", "torso_head"))
    def wait(self) -> None:
        """Sit this operation out."""

    @skill(
        ParamSpec("target", ParamType.TARGET, "where to go"),
        ParamSpec("speed", ParamType.NUMBER, "fraction of full speed", unit="fraction", default="0.5", minimum=0.01, maximum=1.0),
    )
    def move_to(self, target: object, speed: float) -> None:
        """Move the tool to a target."""

    @skill(ParamSpec("pose", ParamType.JOINT_POSE, "a named joint pose"), groups=("arm", "torso_head"))
    def go_to_pose(self, pose: str) -> None:
        """Move the group's joints to a named pose."""

    @skill(ParamSpec("joints", ParamType.JOINTS, "joint values"), groups=("arm", "torso_head"))
    def move_joints(self, joints: object) -> None:
        """Move the group's joints."""

    @skill(ParamSpec("duration", ParamType.NUMBER, "how long", unit="s", minimum=0.0), groups=("arm", "torso_head"))
    def sleep(self, duration: float) -> None:
        """Do nothing for a while."""

    @skill(ParamSpec("pan", ParamType.NUMBER, "head pan", unit="rad"), groups=("torso_head",))
    def look(self, pan: float) -> None:
        """Turn the head."""

    @skill(ParamSpec("pose", ParamType.JOINT_POSE, "whole-robot pose"), groups=("arm", "torso_head"), sync="full_body")
    def full_body_move(self, pose: str) -> None:
        """Move the whole robot at once."""

    @skill(ParamSpec("target", ParamType.TARGET, "where the master goes"), ParamSpec("slave", ParamType.GROUP, "the follower"), sync="master_slave")
    def master_move(self, target: object, slave: str) -> None:
        """Lead a two-arm motion."""

    @skill(ParamSpec("master", ParamType.GROUP, "the leader"), sync="master_slave")
    def slave_follow(self, master: str) -> None:
        """Follow the other arm."""

    @skill(leaves=Hold.NOTHING)
    def open_gripper(self) -> None:
        """Open the gripper."""

    @skill(leaves=Hold.UNKNOWN)
    def close_gripper(self) -> None:
        """Close the gripper on whatever is there."""


class Rivets(Core):
    @skill(ParamSpec("hole", ParamType.FRAME, "the hole", kinds=("hole",)))
    def debur_drilling(self, hole: str) -> None:
        """Find a drilled hole and debur it."""

    @skill(
        ParamSpec("slot", ParamType.FRAME, "the tray slot", kinds=("rivet_slot",)),
        ParamSpec("element", ParamType.ELEMENT, "the rivet reference", kinds=("rivet",)),
        requires=Hold.NOTHING,
        leaves=Hold.PART,
    )
    def pick_rivet(self, slot: str, element: str) -> None:
        """Pick a rivet from a tray slot."""

    @skill(ParamSpec("hole", ParamType.FRAME, "the hole", kinds=("hole",)), requires=Hold.PART, leaves=Hold.NOTHING)
    def insert_rivet(self, hole: str) -> None:
        """Insert the held rivet into a hole."""


def small_catalog() -> Catalog:
    return Catalog.from_classes({"core": Core, "rivets": Rivets})


CELL_XML = """<?xml version="1.0" encoding="UTF-8"?>
<cell name="rivet_cell" length_unit="m" angle_unit="rad">
  <frame name="part" parent="world" xyz="0.45 0.0 0.05" rpy="0 0 0" kind="fixture">
    <frame name="drill_1" xyz="0.02 0.10 0" rpy="3.14159265 0 0" kind="hole" diameter="0.0048">
      <actual xyz="0.0004 -0.0003 0" rpy="0 0 0"/>
    </frame>
    <frame name="drill_2" xyz="0.02 0.14 0" rpy="3.14159265 0 0" kind="hole" diameter="0.0048"/>
  </frame>
  <frame name="rivet_tray" parent="world" xyz="0.35 -0.30 0.02" rpy="0 0 0" kind="tray">
    <frame name="rivet_1" xyz="0 0 0" rpy="3.14159265 0 0" kind="rivet_slot" element="ref_R10"/>
    <frame name="rivet_2" xyz="0.02 0 0" rpy="3.14159265 0 0" kind="rivet_slot" element="ref_R10"/>
  </frame>
  <element name="ref_R10" kind="rivet" diameter="0.0048" length="0.010" grip_depth="0.004"/>
  <joint_pose name="safe" unit="deg" joints="0 0 0  -0.6 0 -100 15.2 9.4 3.2  0.6 0 -100 -15.2 9.4 -3.2"/>
  <joint_pose name="left_ready" group="left_arm" unit="deg" joints="0.6 0 -100 -15.2 9.4 -3.2"/>
</cell>
"""

APP_XML = """<?xml version="1.0" encoding="UTF-8"?>
<application name="rivet_installation" robot="nextage" cell="cells/rivet_cell.xml">
  <description>Debur a hole and install a rivet</description>
  <error_policy retries="1" action="safe_pose" safe_pose="initial" alarm_timeout="0"/>
  <operation id="1">
    <left_arm>
      <function name="debur_drilling">
        <params>
          <param value="drill_1"></param>
        </params>
      </function>
    </left_arm>
    <torso_head><function name="wait"></function></torso_head>
    <right_arm>
      <function name='pick_rivet'>
        <params><param value="rivet_1"/><param value="ref_R10" name="element"/></params>
      </function>
    </right_arm>
  </operation>
  <operation id="2" name="insert">
    <right_arm>
      <function name="insert_rivet"><params><param value="drill_1"/></params></function>
    </right_arm>
  </operation>
  <operation id="3">
    <left_arm><function name="move_to"><params><param value="drill_2"/></params></function></left_arm>
  </operation>
</application>
"""
