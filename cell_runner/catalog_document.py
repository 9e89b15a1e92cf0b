"""The function catalog as one document: what ``functions --json`` prints and the operator station's builder loads.

The XML's shape in a paragraph, what each param type accepts, every robot (groups, joints and their
limits, poses, cameras; degrees) and every function of the catalog, so a person or a tool writing an
application has it all in one place.  ``functions`` without ``--json`` prints the same as text (cli.py).
"""
from __future__ import annotations

import math

from core_functions.catalog import Catalog, ParamType
from core_functions.robots import ROBOTS, RobotModel

XML_USAGE = """\
An application is an XML file: <application name=".." robot="nextage" cell="cells/your_cell.xml">, holding
<operation id="1"> elements in the order they run. In each operation, one element per robot group (Nextage:
left_arm, right_arm, torso_head; single-arm robots: arm) holds one <function name="..."> with its params in order:
<params><param value="..."/></params>. A group left out of an operation waits. Groups of one operation run at the
same time; the next operation starts when all are done. Optional: <error_policy retries="1" action="abort|safe_pose|
alarm" safe_pose="initial"/> before the operations. Numbers are SI (m, rad, s) unless a unit is written after them
(mm, deg, ms, %). Loops repeat operations: <for_each var="hole" in="drill_1 drill_2"> (or in="kind:hole", the cell's
frames of that kind, or in="grid:tray_1 3x4 0.020 0.025", a pallet grid's frames) and <repeat count="3">, with {hole}
and {index} (from 1) replaced in ids, names and param values; <call application="block.xml"><param name="hole"
value="drill_3"/></call> brings in another application's operations. Check a file with: python -m execution_engine
validate FILE"""

PARAM_TYPE_HELP = {
    ParamType.NUMBER: "a number; a unit suffix of the param's unit family may follow (mm, cm, deg, ms, %)",
    ParamType.INTEGER: "a whole number",
    ParamType.BOOLEAN: "true or false (also yes/no, 1/0)",
    ParamType.TEXT: "free text",
    ParamType.CHOICE: "one of the listed choices",
    ParamType.NAME: "a name you choose: letters, digits, _ . -",
    ParamType.FRAME: "the name of a frame of the cell model (of one of the listed kinds, if any)",
    ParamType.FRAMES: "cell frame names separated by spaces or commas",
    ParamType.ELEMENT: "the name of an element (reference) of the cell model",
    ParamType.TARGET: "a cell frame name, or 'x,y,z,roll,pitch,yaw' in the world frame (m, rad; mm/deg suffixes allowed)",
    ParamType.JOINTS: "one value per joint of the group in the robot's order, rad (or 'deg' after the list)",
    ParamType.JOINT_POSE: "a named joint pose of the robot (e.g. initial, off) or a <joint_pose> of the cell",
    ParamType.GROUP: "the name of another group of the robot",
    ParamType.CAMERA: "a camera of the robot (see robots), or auto for the group's own camera",
}


def robot_document(robot: RobotModel) -> dict[str, object]:
    """What an application writer needs of a robot: groups, joints with limits, poses, cameras (degrees)."""
    return {
        "aliases": list(robot.aliases),
        "description": robot.description,
        "workspace": robot.workspace,
        "groups": {
            g.name: {
                "kind": g.kind,
                "camera": g.camera,
                "joints": [{"name": j.name, "min_deg": round(math.degrees(j.lower), 3), "max_deg": round(math.degrees(j.upper), 3)} for j in g.joints],
            }
            for g in robot.groups
        },
        "joint_order": list(robot.joint_names),
        "joint_poses_deg": {name: [round(math.degrees(pose[j]), 3) for j in robot.joint_names] for name, pose in robot.poses.items()},
        "cameras": list(robot.cameras),
    }


def catalog_document(catalog: Catalog) -> dict[str, object]:
    """The catalog with what writing an application needs around it: the XML's shape, the param types, the robots."""
    return {
        "xml_usage": XML_USAGE,
        "param_types": {t.value: PARAM_TYPE_HELP[t] for t in ParamType},
        "robots": {r.name: robot_document(r) for r in ROBOTS},
        "functions": catalog.describe(),
    }
