"""``python -m execution_engine camera-sim APP.xml``: the robot's cameras for a ros2_control mock robot.

A mock robot (mock_components/GenericSystem, a fake driver) moves its joints but has no cameras, so
an application whose skills locate features by vision cannot run on it through the ros2-control
back end's ``camera_source=ros``.  This node gives it cameras as the Nextage simulator has them: it
follows ``/joint_states``, places every camera of the application's robot where the URDF's forward
kinematics put its link at the latest joint states (a camera whose link is a cell frame stands
there), renders what it sees of the application's cell -- the parts' true poses, ``<actual>``
offsets included -- and publishes ``<camera>/image_raw`` (mono8) and ``<camera>/camera_info`` at a
fixed rate (``--rate``; a camera that has not moved since its last image is not drawn again), sensor-data QoS, stamped with the joint states it was rendered from, so a
client that skips images older than its request (the back end does) never sees one taken while the
arm was still moving.  The URDF is ``/robot_description`` (robot_state_publisher's) or ``--urdf``.
"""
from __future__ import annotations

import asyncio
from collections.abc import Mapping
from typing import IO

import numpy as np

from app_functions.registry import full_catalog
from cell_runner.camera_sim_cli import CameraSimSettings
from cell_runner.ros_main import NodeBody, Outcome, StartupError, run_node, startup_errors
from execution_engine.app_model import ApplicationError, load_application
from node_transport.msgs import JointState, String
from node_transport.port import Node, poll_until
from node_transport.qos import ROBOT_DESCRIPTION
from node_transport.wire import CellSnapshot
from robot_bridges.camera.render import render
from robot_bridges.camera.ros_camera import ImagePublisher
from robot_bridges.camera.scene import build_scene
from robot_bridges.camera.sources import Frame
from robot_bridges.ros2_control.cameras import RobotCameras, camera_pose, robot_cameras
from robot_bridges.ros2_control.link import STATE_QOS
from robot_bridges.ros2_control.model import UrdfModel

NODE_NAME = "camera_sim"
EXIT_FAILED, EXIT_USAGE = 1, 2


def cmd_camera_sim(settings: CameraSimSettings, out: IO[str], err: IO[str]) -> int:
    """Check the application (one line), then serve until SIGINT/SIGTERM."""
    try:
        app = load_application(settings.file, full_catalog())
        cameras = chosen_cameras(settings, robot_cameras(app.robot), app.robot.name)
    except ApplicationError as error:
        first = error.diagnostics[0] if error.diagnostics else settings.file
        err.write(f"error: {first} (camera-sim needs a valid application: validate shows every problem)\n")
        return EXIT_FAILED
    except (ValueError, OSError) as error:
        err.write(f"error: camera-sim: {error}\n")
        return EXIT_USAGE
    topics = {name: settings.topics.get(name, name) for name in cameras.specs}
    out.write(f"camera-sim: {', '.join(f'{t}/image_raw' for t in topics.values())} at {settings.rate:g} Hz\n")
    out.flush()
    body = camera_body(settings, cameras, topics, app.cell.to_snapshot(app.robot))
    return run_node(NODE_NAME, body, [NODE_NAME, "--transport", settings.transport])


def chosen_cameras(settings: CameraSimSettings, known: RobotCameras | None, robot: str) -> RobotCameras:
    if known is None:
        raise ValueError(f"robot {robot} has no camera model")
    unknown = [c for c in settings.cameras if c not in known.specs]
    if unknown:
        raise ValueError(f"--camera {unknown[0]}: robot {robot} has no such camera (cameras: {', '.join(known.specs)})")
    names = settings.cameras or tuple(known.specs)
    return RobotCameras({n: known.specs[n] for n in names}, {})


def camera_body(settings: CameraSimSettings, cameras: RobotCameras, topics: Mapping[str, str], cell: CellSnapshot) -> NodeBody:
    """The node's life: the URDF, then every ``1/rate`` s each camera rendered at the latest joint states and published."""

    async def body(node: Node, outcome: Outcome) -> None:
        with startup_errors():
            publish = ImagePublisher(node, topics)
            scene = build_scene(cell.frames, cell.elements, cell.truth)
        states: dict[str, float] = {}
        stamp = [0.0]

        def on_states(msg: JointState) -> None:
            if len(msg.name) == len(msg.position):
                states.update(zip(msg.name, (float(v) for v in msg.position)))
                stamp[0] = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9

        node.create_subscription(JointState, "/joint_states", on_states, STATE_QOS)
        with startup_errors():
            model = UrdfModel(await robot_description(node, settings))
        rng = np.random.default_rng(settings.seed)
        drawn: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # camera -> (its pose, the image drawn there)
        period = 1.0 / settings.rate
        clock = node.clock
        due = clock.now()
        while True:
            if states:
                q = np.array([states.get(name, 0.0) for name in model.joint_names])
                taken = stamp[0] or node.now_stamp().to_seconds()
                for spec in cameras.specs.values():
                    pose = camera_pose(spec, model, q, cell)
                    if pose is None:
                        raise StartupError(f"{spec.name}: its link {spec.link!r} is neither a link of the URDF nor a frame of the cell")
                    last = drawn.get(spec.name)
                    if last is None or not np.allclose(last[0], pose.matrix(), rtol=0.0, atol=1e-9):  # a still camera: the same image
                        last = drawn[spec.name] = (pose.matrix(), await asyncio.to_thread(render, scene, spec.intrinsics, pose.matrix(), spec.optics, rng))
                    publish(spec, pose, Frame(last[1], spec.intrinsics, taken))
            due = max(due + period, clock.now())
            await clock.sleep_until(due)

    return body


async def robot_description(node: Node, settings: CameraSimSettings) -> str:
    if settings.urdf is not None:
        with open(settings.urdf, encoding="utf-8") as file:
            return file.read()
    found: list[str] = []
    node.create_subscription(String, "/robot_description", lambda m: found.append(m.data), ROBOT_DESCRIPTION)
    if not await poll_until(node.clock, lambda: bool(found), settings.start_timeout, 0.05):
        raise StartupError(f"no /robot_description in {settings.start_timeout:g} s: is robot_state_publisher running in this ROS_DOMAIN_ID? Or give --urdf FILE")
    return found[-1]

