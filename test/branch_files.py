"""The files docs/faults.md's rows 240-249 name under {tmp}: applications whose outcome branches
(<if>/<else>, issue 24 item 2) are refused, each at its line, and one whose branch the simulator
would not take meets a collision in the dry run."""
from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "apps_xml" / "cells" / "rivet_cell.xml"
BRANCH = (ROOT / "apps_xml" / "rivet_loop_branch.xml").read_text()
PUT_BACK = '<right_arm><function name="place"><params><param value="rivet_{index}"/></params></function></right_arm>'

#: Line 3 looks at each hole (the left arm's locate, the right arm's wait): the <if>s below test it.
LOOK = (
    '  <for_each var="hole" in="drill_1 drill_2">\n'
    '    <operation id="look_{hole}"><left_arm><function name="locate"><params><param value="{hole}"/></params></function></left_arm></operation>\n'
)
SKIP = '<operation id="skip_{hole}"><right_arm><function name="gripper_open"/></right_arm></operation>'


def _app(body: str) -> str:
    return f'<?xml version="1.0"?>\n<application name="t" robot="nextage" cell="{CELL}">\n{LOOK}{body}  </for_each>\n</application>\n'


def _if(attributes: str, inner: str = SKIP) -> str:
    return f"    <if {attributes}>{inner}</if>\n"


BRANCH_FILES: dict[str, str] = {
    "if_later.xml": _app(_if('group="left_arm" operation="look_drill_2" outcome="found"')),
    "if_outcome.xml": _app(_if('group="left_arm" operation="look_{hole}" outcome="in_range"')),
    "if_waits.xml": _app(_if('group="right_arm" operation="look_{hole}" outcome="found"')),
    "if_group.xml": _app(_if('group="arm" operation="look_{hole}" outcome="found"')),
    "else_alone.xml": _app(f"    <else>{SKIP}</else>\n"),
    "else_twice.xml": _app(_if('group="left_arm" operation="look_{hole}" outcome="found"', SKIP.replace("skip_", "found_")) + f"    <else>{SKIP}</else>\n"
                           + f"    <else>{SKIP.replace('skip_', 'again_')}</else>\n"),
    "if_never.xml": _app(_if('group="left_arm" operation="look_{hole}" outcome="found"',
                             f'<if group="left_arm" operation="look_{{hole}}" outcome="not_found">{SKIP}</if>')),
    "if_no_outcome.xml": _app(_if('group="left_arm" operation="look_{hole}"')),
    "branch_collide.xml": BRANCH.replace('cell="cells/rivet_cell.xml"', f'cell="{CELL}"').replace(
        PUT_BACK, '<right_arm><function name="place"><params><param value="0.34,-0.02,-0.004,3.14159265,0,0"/></params></function></right_arm>'
    ),
}
