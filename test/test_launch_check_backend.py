"""Under ``launch``, the engine checks each run on the model of the back end the bridge drives, with its options.

``launch APP --robot ros2-control --backend-option ...`` starts the ros2_control_bridge; the engine, another
process, dry-runs every run from the measured joints first.  That dry run must be the one ``run --robot
ros2-control`` does (the URDF model, the group's controller, tool and gripper), not the robot model's default
back end (for the KUKA the RSI simulator, which would even run an RSI loop inside the engine).  Here the
engine's command line as the launcher builds it is parsed as the engine process parses it, the engine node is
built on it, and its start check's dry-run setup is looked at.
"""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
from test_launch_ros2_control import CELL, CONTROLLER, GRIPPER, URDF_FILE  # CELL: that KUKA as a cell's robot 'loader', prefixed kuka_

from cell_runner.dry_run.simulators import DryRunSetup
from cell_runner.dry_run.start import StartRefused
from cell_runner.engine_check import options_from_text, options_text
from cell_runner.launcher import NodeSpec, cell_nodes
from cell_runner.libraries import APPLICATION_FUNCTIONS
from cell_runner.nodes import declare_engine_parameters, engine_starts
from core_functions.cell_robots import CellRobotModel
from execution_engine.app_model import load_application
from execution_engine.engine.engine import ExecutionEngine
from node_transport.clock import Clock
from node_transport.dds_args import parse_ros_arguments
from node_transport.local import LocalTransport
from node_transport.wire import ENGINE_NODE

ROOT = Path(__file__).resolve().parent.parent
KUKA_APP = ROOT / "apps_xml" / "kuka_rsi_demo.xml"
CELL_APP = """<?xml version="1.0" encoding="UTF-8"?>
<application name="driven" robot="cell" cell="driven_cell.xml">
  <operation id="1"><kuka_arm><function name="move_to_joint_pose"><params><param value="home"/></params></function></kuka_arm></operation>
</application>
"""


@pytest.fixture(autouse=True)
def private_data_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))


def engine_of(specs: list[NodeSpec]) -> NodeSpec:
    return next(spec for spec in specs if spec.name == ENGINE_NODE)


def engine_setup(run_sim: Any, spec: NodeSpec, app: Path) -> DryRunSetup:
    """The dry-run setup the engine started with ``spec``'s command line (params file and -p, as it parses them) checks ``app`` on."""
    parameters = parse_ros_arguments(spec.argv).overrides_for(f"/{ENGINE_NODE}")

    async def main(clock: Clock) -> DryRunSetup:
        node = LocalTransport(clock).create_node(ENGINE_NODE, parameters=parameters)
        settings = declare_engine_parameters(node)
        starts = engine_starts(node, ExecutionEngine(node, APPLICATION_FUNCTIONS.catalog(None)), settings)
        assert starts is not None and node.undeclared_overrides() == []
        return starts.setup(load_application(app, APPLICATION_FUNCTIONS.catalog(None)))

    return run_sim(main)


def test_the_engine_of_a_ros2_control_launch_checks_on_the_urdf_model_with_the_bridges_options(run_sim: Any) -> None:
    options = (("arm.controller", CONTROLLER), ("arm.gripper", GRIPPER), ("arm.tool", "0 0 0.1 0 0 0"))
    setup = engine_setup(run_sim, engine_of(cell_nodes(KUKA_APP, "dds", 1.0, backend="ros2-control", options=options)), KUKA_APP)
    assert setup.backend == "ros2-control"  # not kuka-rsi: no RSI simulator in the engine
    extra = setup.options.extra
    assert extra["transport"] == "model" and extra["description"] == "dds"  # the URDF from /robot_description, as run's dry run
    assert {k: extra[k] for k, _ in options} == dict(options)
    assert setup.unkept  # a model read off the graph is never a kept verdict


def test_a_urdf_file_whose_name_yaml_would_misread_reaches_the_engines_check_unchanged(run_sim: Any, tmp_path: Path) -> None:
    urdf = tmp_path / "kr6 #1: copy.urdf"
    shutil.copy(URDF_FILE, urdf)
    options = (("urdf", str(urdf)), ("arm.controller", CONTROLLER))
    setup = engine_setup(run_sim, engine_of(cell_nodes(KUKA_APP, "dds", 1.0, backend="ros2-control", options=options)), KUKA_APP)
    assert setup.options.extra["urdf"] == str(urdf) and setup.options.extra["transport"] == "model"
    assert not setup.unkept  # the URDF is a file: its verdict can be kept


def test_without_a_back_end_given_the_engine_checks_on_the_robots_default_one(run_sim: Any) -> None:
    spec = engine_of(cell_nodes(KUKA_APP, "dds", 1.0))
    assert not any(a.startswith(("check_backend:=", "check_options:=")) for a in spec.argv)  # the command line as before
    assert engine_setup(run_sim, spec, KUKA_APP).backend == "kuka-rsi"


def test_no_check_passes_no_check_back_end() -> None:
    spec = engine_of(cell_nodes(KUKA_APP, "dds", 1.0, check=False, backend="ros2-control", options=(("arm.controller", CONTROLLER),)))
    assert "check:=false" in spec.argv and not any(a.startswith(("check_backend:=", "check_options:=")) for a in spec.argv)


def test_a_cell_checks_each_robot_on_its_own_back_end_and_options(run_sim: Any, tmp_path: Path) -> None:
    (tmp_path / "driven_cell.xml").write_text(CELL)
    app = tmp_path / "driven.xml"
    app.write_text(CELL_APP)
    spec = engine_of(cell_nodes(app, "dds", 1.0))
    assert not any(a.startswith("check_backend:=") for a in spec.argv)
    setup = engine_setup(run_sim, spec, app)
    robot = setup.options.robot
    assert setup.backend == "cell" and isinstance(robot, CellRobotModel)
    (member,) = robot.members
    assert member.backend == "ros2-control"
    assert {"transport": "model", "arm.controller": CONTROLLER, "arm.gripper": GRIPPER}.items() <= dict(member.options).items()


def test_a_back_end_option_the_engine_cannot_carry_is_refused_by_the_launch() -> None:
    with pytest.raises(ValueError, match=r"^--backend-option arm.tool=0;1: the engine's check cannot be given a ';' \(its parameter check_options"):
        options_text((("arm.tool", "0;1"),))
    assert options_from_text(options_text((("a", "x = y"), ("b", "")))) == {"a": "x = y", "b": ""}
    with pytest.raises(ValueError, match=r"^parameter check_options: 'nonsense' is not KEY=VALUE"):
        options_from_text("a=1;nonsense")


def test_a_check_option_the_back_end_refuses_refuses_the_run_naming_it(run_sim: Any) -> None:
    spec = NodeSpec(ENGINE_NODE, ("--ros-args", "-p", "check_backend:=ros2-control", "-p", "check_options:=arm.gripper_open=banana"))
    with pytest.raises(StartRefused, match=r"^parameters check_backend/check_options: .*gripper_open"):
        engine_setup(run_sim, spec, KUKA_APP)


def test_a_cell_given_a_check_back_end_is_refused_naming_the_parameters(run_sim: Any, tmp_path: Path) -> None:
    """A cell's robots each have their back end in the cell: one back end for all of them would check another cell."""
    (tmp_path / "driven_cell.xml").write_text(CELL)
    app = tmp_path / "driven.xml"
    app.write_text(CELL_APP)
    spec = NodeSpec(ENGINE_NODE, ("--ros-args", "-p", "check_backend:=ros2-control"))
    with pytest.raises(StartRefused, match=r"^parameters check_backend/check_options: driven runs a cell of several robots"):
        engine_setup(run_sim, spec, app)
