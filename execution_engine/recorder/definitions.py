"""ROS 2 message definitions (``ros2msg``) of every type the project publishes, as data.

A recording must carry each type's schema the way ``ros2 bag record -s mcap`` writes it, so that
Foxglove, PlotJuggler and ``ros2 bag`` decode it without the ROS packages installed: the type's
own ``.msg`` text followed by every type it depends on, each after a line of 80 ``=`` and a
``MSG: pkg/Name`` line (rosbag2's ``LocalMessageDefinitionSource``).  There is no ROS install
here to read the ``.msg`` files from, so their field lines (the public interface definitions of
ROS 2 Jazzy's common_interfaces, rcl_interfaces and geometry2; comments left out) are kept here.
"""
from __future__ import annotations

import re
from functools import lru_cache

from node_transport.idl import InterfaceError, InterfaceRegistry

SEPARATOR = "=" * 80

#: ``pkg/Name`` -> the field and constant lines of its ``.msg`` file.
DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "rosgraph_msgs/Clock": "builtin_interfaces/Time clock\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "std_msgs/Bool": "bool data\n",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
    ),
    "sensor_msgs/RegionOfInterest": "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
    "sensor_msgs/Image": (
        "std_msgs/Header header\n\nuint32 height\nuint32 width\n\nstring encoding\n\nuint8 is_bigendian\nuint32 step\n\nuint8[] data\n"
    ),
    "sensor_msgs/CameraInfo": (
        "std_msgs/Header header\n\nuint32 height\nuint32 width\n\nstring distortion_model\n\nfloat64[] d\n\nfloat64[9]  k\n\n"
        "float64[9]  r\n\nfloat64[12] p\n\nuint32 binning_x\nuint32 binning_y\n\nRegionOfInterest roi\n"
    ),
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "diagnostic_msgs/KeyValue": "string key\nstring value\n",
    "diagnostic_msgs/DiagnosticStatus": (
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n\nbyte level\nstring name\nstring message\n"
        "string hardware_id\nKeyValue[] values\n"
    ),
    "diagnostic_msgs/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status\n",
}

_PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
    "int64", "uint64", "string", "wstring",
})
_FIELD = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_/]*)(?:<=\d+)?(?:\[[^\]]*\])?\s+[A-Za-z_]")


#: packages whose definitions are the interface files installed with this project (their .msg text)
OWN_PACKAGES = frozenset({"dual_arm_executive_interfaces"})


@lru_cache(maxsize=None)
def _own(name: str) -> str | None:
    """The field and constant lines of one of the project's own messages, read from its .msg file."""
    package, _, message = name.partition("/")
    if package not in OWN_PACKAGES:
        return None
    try:
        text = InterfaceRegistry().file_text(package, "msg", message)
    except InterfaceError:
        return None
    return "".join(line + "\n" for line in (raw.split("#", 1)[0].rstrip() for raw in text.splitlines()) if line)


def definition(name: str) -> str:
    """The .msg text of ``pkg/Name``; KeyError when neither the table nor the project's files have it."""
    text = DEFINITIONS.get(name) or _own(name)
    if text is None:
        raise KeyError(name)
    return text


def short_name(ros_type: str) -> str:
    """``pkg/msg/Name`` -> ``pkg/Name`` (how ``MSG:`` lines and field types spell it)."""
    parts = ros_type.split("/")
    return f"{parts[0]}/{parts[-1]}"


def dependencies(name: str) -> list[str]:
    """The types ``name`` uses, depth first in order of appearance, each once (rosbag2's order)."""
    seen: list[str] = []

    def visit(current: str) -> None:
        package = current.split("/")[0]
        for line in definition(current).splitlines():
            match = _FIELD.match(line)
            if match is None:  # a blank line (constants are always of primitive types)
                continue
            field_type = match.group(1)
            if field_type in _PRIMITIVES:
                continue
            full = field_type if "/" in field_type else f"{package}/{field_type}"
            if full not in seen:
                seen.append(full)
                visit(full)

    visit(name)
    return seen


def known(ros_type: str) -> bool:
    """Whether this table can describe ``ros_type`` (a recorder skips, and says so, what it cannot)."""
    name = short_name(ros_type)
    return name in DEFINITIONS or _own(name) is not None


def schema_text(ros_type: str) -> str:
    """The ``ros2msg`` schema of ``ros_type`` (``sensor_msgs/msg/JointState``) as rosbag2 stores it;
    KeyError for a type this table does not know."""
    name = short_name(ros_type)
    parts = [definition(name)]
    for dependency in dependencies(name):
        parts.append(f"{SEPARATOR}\nMSG: {dependency}\n{definition(dependency)}")
    return "".join(parts)
