"""The files docs/faults.md's rows 250-259 name under {tmp}: mixed cells (a cell listing its robots) that
are refused, and the applications that run on them (robot="cell")."""
from __future__ import annotations


def cell_text(*robots: str, name: str = "mixed") -> str:
    return f'<?xml version="1.0"?>\n<cell name="{name}" length_unit="m" angle_unit="rad">\n' + "".join(f"  {r}\n" for r in robots) + "</cell>\n"


def app_text(cell: str, group: str = "arm", name: str = "mixed") -> str:
    return (
        f'<?xml version="1.0"?>\n<application name="{name}" robot="cell" cell="{cell}">\n'
        f'  <operation id="1"><{group}><function name="wait"><params><param value="0.1"/></params></function></{group}></operation>\n'
        "</application>\n"
    )


KUKA = '<robot name="feeder" model="kuka" backend="kuka-rsi" xyz="0.35 -0.9 -0.1" rpy="0 0 1.57"/>'
NEXTAGE = '<robot name="assembler" model="nextage" backend="nextage-sim" xyz="0 0 0" rpy="0 0 0"/>'

MIXED_FILES: dict[str, str] = {
    "mc_backend_cell.xml": cell_text(KUKA.replace('backend="kuka-rsi"', 'backend="fanuc-rsi"'), NEXTAGE),
    "mc_backend.xml": app_text("mc_backend_cell.xml"),
    "mc_groups_cell.xml": cell_text(KUKA, KUKA.replace('name="feeder"', 'name="second"')),
    "mc_groups.xml": app_text("mc_groups_cell.xml"),
    "mc_nogroup_cell.xml": cell_text(KUKA),
    "mc_nogroup.xml": app_text("mc_nogroup_cell.xml", "left_arm"),
    "mc_base_cell.xml": cell_text(KUKA.replace(' rpy="0 0 1.57"', ""), NEXTAGE),
    "mc_base.xml": app_text("mc_base_cell.xml"),
    "mc_model_cell.xml": cell_text(KUKA.replace('model="kuka"', 'model="kuka_kr1000"'), NEXTAGE),
    "mc_model.xml": app_text("mc_model_cell.xml"),
    "mc_twice_cell.xml": cell_text(KUKA, NEXTAGE.replace('name="assembler"', 'name="feeder"')),
    "mc_twice.xml": app_text("mc_twice_cell.xml"),
    "mc_none_cell.xml": cell_text('<frame name="table" xyz="0.3 0 0"/>'),
    "mc_none.xml": app_text("mc_none_cell.xml"),
    "mc_option_cell.xml": cell_text(KUKA.replace("/>", '><option name="cycel" value="4"/></robot>'), NEXTAGE),
    "mc_option.xml": app_text("mc_option_cell.xml"),
}
