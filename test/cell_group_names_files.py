"""The files docs/faults.md's rows 300-309 name under {tmp}: cells that name their robots' groups and joints
(``<robot prefix>``, ``<group name as>``) with a clash left, and the applications that run on them."""
from __future__ import annotations

from mixed_cell_files import app_text, cell_text


def _cell(*robots: str) -> str:
    return cell_text(*robots, name="named")


def _app(cell: str, group: str = "kuka_arm") -> str:
    return app_text(cell, group, name="named")


KUKA = '<robot name="loader" model="kuka" backend="kuka-rsi" xyz="0 0 0" rpy="0 0 0" prefix="kuka_"/>'
VIPER = '<robot name="checker" model="viper" backend="vplus" xyz="1.5 0 0" rpy="0 0 3.14159265" prefix="viper_">{}</robot>'

NAMED_FILES: dict[str, str] = {
    "cg_taken_cell.xml": _cell(KUKA, VIPER.format('<group name="arm" as="kuka_arm"/>')),
    "cg_taken.xml": _app("cg_taken_cell.xml"),
    "cg_lacks_cell.xml": _cell(KUKA, VIPER.format('<group name="gripper" as="hand"/>')),
    "cg_lacks.xml": _app("cg_lacks_cell.xml"),
    "cg_joints_cell.xml": _cell(
        '<robot name="left" model="kuka" xyz="0 0.8 0" rpy="0 0 0"><group name="arm" as="left_kuka"/></robot>',
        '<robot name="right" model="kuka" xyz="0 -0.8 0" rpy="0 0 0"><group name="arm" as="right_kuka"/></robot>',
    ),
    "cg_joints.xml": _app("cg_joints_cell.xml", "left_kuka"),
    "cg_own_cell.xml": _cell(KUKA, VIPER.format("")),
    "cg_own.xml": _app("cg_own_cell.xml", "arm"),
    "cg_typo_cell.xml": _cell(KUKA, VIPER.format("")),
    "cg_typo.xml": _app("cg_typo_cell.xml", "kuka_amr"),
}
