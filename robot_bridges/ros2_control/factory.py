"""The ``ros2-control`` back end as the registry builds it: options, the link to the ROS graph, the back end.

``transport=dds`` (the default) joins the ROS graph as a Cyclone DDS participant -- no ROS install
needed, rmw_cyclonedds_cpp's wire -- in ``ROS_DOMAIN_ID``; ``transport=ros`` as an rclpy node (inside a
sourced ROS 2).  The link has a transport of its own: in ``run`` the cell's nodes talk in-process
while the back end talks to the robot's driver on the graph.  ``transport=model`` is the dry run's:
the URDF model is the robot (the URDF from ``urdf=FILE``, or read once from ``/robot_description``),
and with ``camera_source=ros`` its cameras render the cell as the Nextage simulator's do.
"""
from __future__ import annotations

import asyncio
import math
from collections.abc import Mapping

import numpy as np

from core_functions.robots import RobotModel
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.msgs import String
from node_transport.port import Transport, poll_until
from node_transport.qos import ROBOT_DESCRIPTION
from node_transport.ros import RosTransport  # rclpy itself is imported only when one starts
from robot_bridges.backend import BackendOptions
from robot_bridges.camera.render import Scene
from robot_bridges.camera.ros_camera import RosCamera
from robot_bridges.camera.sources import CameraSource, RenderedCamera
from robot_bridges.ros2_control.backend import Ros2ControlBackend, group_chains
from robot_bridges.ros2_control.link import GraphLink, ModelLink
from robot_bridges.ros2_control.model import UrdfModel
from robot_bridges.ros2_control.options import Ros2ControlSettings, parse_options

__all__ = ["create", "parse_options", "OwnTransportLink"]

NODE_NAME = "ros2_control_client"


def graph_transport(kind: str, clock: Clock) -> Transport:
    """The transport the back end joins the ROS graph with."""
    if kind == "ros":
        return RosTransport(clock, [])
    return DdsTransport(clock, [])


class OwnTransportLink(GraphLink):
    """A graph link on a transport of its own, shut down with the back end."""

    def __init__(self, transport: Transport, settings: Ros2ControlSettings) -> None:
        super().__init__(transport.create_node(NODE_NAME), settings)
        self.transport = transport

    async def close(self) -> None:
        await self.transport.shutdown()


def read_description(kind: str, timeout: float) -> str:
    """``/robot_description`` read once from the graph (on its own loop, in wall time): the dry run's URDF."""

    async def main(clock: Clock) -> str:
        transport = graph_transport(kind, clock)
        found: list[str] = []
        try:
            transport.create_node(f"{NODE_NAME}_description").create_subscription(String, "/robot_description", lambda m: found.append(m.data), ROBOT_DESCRIPTION)
            if not await poll_until(clock, lambda: bool(found), timeout, 0.02):
                raise ConnectionError(f"ros2-control: no /robot_description in {timeout:g} s (start_timeout): is robot_state_publisher running "
                                      "in this ROS_DOMAIN_ID? Or give the URDF with the option urdf=FILE")
            return found[-1]
        finally:
            await transport.shutdown()

    return run_with_clock(main, real_clock())


def start_pose(robot: RobotModel, settings: Ros2ControlSettings, model: UrdfModel) -> Mapping[str, float]:
    """Where the modelled robot starts: the robot's initial (or home) pose, else each joint's zero within its range."""
    named = next((robot.poses[p] for p in ("initial", "home") if p in robot.poses), {})
    start = {name: min(max(0.0, r.lower), r.upper) for name, r in model.ranges.items()}
    for group in settings.groups:
        for app_name, joint in zip(group.app_joints, group.joints):
            if app_name in named:
                start[joint] = float(np.clip(named[app_name], model.ranges[joint].lower, model.ranges[joint].upper)) if joint in model.ranges else named[app_name]
    return start


async def create(clock: Clock, options: BackendOptions) -> Ros2ControlBackend:
    settings = parse_options(options, math.inf if options.extra.get("transport") == "model" else 1.0)
    if settings.transport == "model":
        if settings.urdf is not None:
            with open(settings.urdf, encoding="utf-8") as file:
                urdf = file.read()
        else:
            urdf = await asyncio.to_thread(read_description, settings.description, settings.start_timeout)
        model, _ = group_chains(urdf, settings)  # UrdfError, a ValueError: refused like a bad option
        link: GraphLink | ModelLink = ModelLink(clock, settings, urdf, start_pose(options.robot, settings, model))
    else:
        link = OwnTransportLink(graph_transport(settings.transport, clock), settings)
    backend = Ros2ControlBackend(clock, options.robot, settings, link)
    if settings.camera_source == "ros":
        # the dry run renders the cell as a simulator's cameras do; a run takes the images the topics bring
        source: CameraSource = (RenderedCamera(lambda: backend.cameras.scene() if backend.cameras else Scene(), options.seed, clock.now)
                                if isinstance(link, ModelLink) else RosCamera(link.node, settings.camera_topics, settings.camera_timeout, fresh=True))
        backend.use_cameras(source)
    return backend
