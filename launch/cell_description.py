"""What the package's launch files share: one cell, one node per process, every node in one namespace.

Not a launch file (``ros2 launch`` offers only ``*.launch.py``): each ``<back end>.launch.py``
beside it runs it with ``runpy.run_path``, because launch files are loaded by path and cannot
import their neighbours.  A launch file describes its back end -- the bridge executable, the robot
and its groups, the YAML, the default application, its own launch arguments and what they set on
the bridge -- and :func:`cell_description` adds the rest:

* the nodes: the bridge (named like its executable), one ``group_machine`` per group named
  ``<group>_machine`` with ``group`` and ``robot`` set, and ``execution_engine``; each takes its
  section of ``config/<back end>.yaml`` first, then what the launch arguments set;
* the launch arguments every ROS user expects: ``application``, ``namespace`` (every node),
  ``use_sim_time`` (the bool parameter of every node; ``/clock`` is remapped to
  ``<namespace>/clock``, so each cell follows its own clock) and ``log_level``
  (``--ros-args --log-level``);
* a simulator that runs at another speed than real time is the cell's clock: it publishes
  ``/clock``, and the machines and the engine then follow it (``use_sim_time`` true whatever the
  argument says), so their timeouts and the engine's report are in the robot's time.

Launch arguments reach parameters through :func:`typed`: launch_ros would otherwise read them
with YAML rules, and ``host:=off`` would arrive as the bool ``false``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, OrSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

PACKAGE = "dual_arm_executive"
LOG_LEVELS = ["debug", "info", "warn", "error", "fatal"]


def typed(argument: str, value_type: type) -> ParameterValue:
    """The value of launch argument ``argument`` as a parameter of ``value_type`` (str, int, float, bool)."""
    return ParameterValue(LaunchConfiguration(argument), value_type=value_type)


def _ros_arguments() -> list:
    return [
        DeclareLaunchArgument(
            "namespace",
            default_value="",
            description="ROS namespace of every node of the cell ('' = the root); cells in different namespaces run side by side",
        ),
        DeclareLaunchArgument(
            "use_sim_time",
            default_value="false",
            description="true: every node takes its ROS time from <namespace>/clock (/clock is remapped there)",
        ),
        DeclareLaunchArgument("log_level", default_value="info", choices=LOG_LEVELS, description="log level of every node (--ros-args --log-level)"),
    ]


def _node(executable: str, name: str, config: str, overrides: dict, sim_time: ParameterValue) -> Node:
    """One node of the cell in ``namespace``: the YAML section named like the node, then ``overrides``."""
    return Node(
        package=PACKAGE,
        executable=executable,
        name=name,
        namespace=LaunchConfiguration("namespace"),
        parameters=[config, {**overrides, "use_sim_time": sim_time}],
        remappings=[("/clock", "clock")],  # rclpy's time source reads /clock: each cell follows its own
        ros_arguments=["--log-level", LaunchConfiguration("log_level")],
        output="screen",
    )


def cell_description(
    *,
    config: str,
    robot: str,
    groups: tuple,
    bridge: str,
    application: str,
    arguments: list,
    bridge_parameters: dict,
    simulated: object = None,
) -> LaunchDescription:
    """The cell of one back end.

    ``config``: the YAML in ``share/<package>/config``; ``robot`` and ``groups``: the robot model
    the machines drive; ``bridge``: the bridge executable (and node name); ``application``: the
    default application in ``share/<package>/apps_xml``; ``arguments``: the back end's own
    ``DeclareLaunchArgument``s; ``bridge_parameters``: the bridge parameters they set;
    ``simulated``: a substitution that is ``true`` when the bridge's simulator runs at another
    speed than real time and publishes ``/clock`` (None: it never does), which the machines and
    the engine then follow.
    """
    share = get_package_share_directory(PACKAGE)
    config_file = os.path.join(share, "config", config)
    own_time = typed("use_sim_time", bool)
    following = own_time if simulated is None else ParameterValue(OrSubstitution(LaunchConfiguration("use_sim_time"), simulated), value_type=bool)
    actions = [
        DeclareLaunchArgument(
            "application",
            default_value=os.path.join(share, "apps_xml", application),
            description="application XML file the engine runs",
        ),
        *arguments,
        *_ros_arguments(),
        _node(bridge, bridge, config_file, bridge_parameters, own_time),
    ]
    for group in groups:
        actions.append(_node("group_machine", f"{group}_machine", config_file, {"group": group, "robot": robot}, following))
    actions.append(_node("execution_engine", "execution_engine", config_file, {"application": typed("application", str)}, following))
    return LaunchDescription(actions)
