"""The files docs/faults.md's rows 260-269 name under {tmp}: applications whose breakpoints (break="true" on an
<operation>, issue 26 item 1) are refused at their line, and one whose breakpoint nobody can continue."""
from __future__ import annotations

OPEN = '<left_arm><function name="gripper_open"/></left_arm>'


def _app(body: str) -> str:
    return f'<?xml version="1.0"?>\n<application name="t" robot="nextage">\n{body}</application>\n'


BREAKPOINT_FILES: dict[str, str] = {
    "break_value.xml": _app(f'  <operation id="1" break="yes">{OPEN}</operation>\n'),
    "break_loop.xml": _app(f'  <repeat count="2" break="true">\n    <operation id="open_{{index}}">{OPEN}</operation>\n  </repeat>\n'),
    "break_run.xml": _app(f'  <operation id="1" break="true">{OPEN}</operation>\n  <operation id="2">{OPEN}</operation>\n'),
}
