"""The cameras of a robot driven through ros2_control: which there are, where each one is, where its images come from.

A FollowJointTrajectory driver knows nothing of cameras, so they come from two places: the robot's
camera models this project has (the Nextage's hand cameras and head pair, the same specs the Nextage
simulator renders: mount link, hand-eye mount, intrinsics, lens), and the back end's options
(``camera_source=ros``, per camera ``CAMERA.topic`` and ``CAMERA.mount``).  A capture places each camera
where the URDF's forward kinematics put its link at the joint states of that moment -- the hand camera
moves with the arm -- or, for a camera fixed in the cell, where the cell frame its link names is.
The images are those of ``<topic>/image_raw`` with ``<topic>/camera_info`` (a real driver, or
``camera-sim`` rendering the cell for a mock robot); the dry run renders the cell instead.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from core_functions.geometry import Pose
from core_functions.robots import RobotModel
from node_transport.wire import CellSnapshot
from robot_bridges.camera.spec import CameraSpec
from robot_bridges.nextage_sim import vision as nextage_vision
from robot_bridges.ros2_control.model import UrdfModel, Vector


@dataclass(frozen=True)
class RobotCameras:
    """A robot's cameras: those taking images, and the names that stand for a stereo pair of them."""

    specs: Mapping[str, CameraSpec]
    stereo: Mapping[str, tuple[str, str]]

    def taking_part(self, name: str) -> tuple[CameraSpec, ...]:
        """The cameras a request naming ``name`` uses (both of a stereo pair); KeyError for an unknown one."""
        return tuple(self.specs[n] for n in self.stereo.get(name, (name,)))

    def mounted(self, mounts: Mapping[str, Pose]) -> RobotCameras:
        """The same cameras with these hand-eye mounts (optical frame in the link) instead of the defaults."""
        return RobotCameras({n: dataclasses.replace(c, mount=mounts[n]) if n in mounts else c for n, c in self.specs.items()}, self.stereo)


#: robot model name -> its cameras, as the project models them.
KNOWN: dict[str, RobotCameras] = {
    "nextage_open": RobotCameras(nextage_vision.REAL_CAMERAS, nextage_vision.STEREO),
}


def robot_cameras(robot: RobotModel) -> RobotCameras | None:
    return KNOWN.get(robot.name)



def camera_pose(spec: CameraSpec, model: UrdfModel, q: Vector, cell: CellSnapshot | None) -> Pose | None:
    """The camera's optical frame in the URDF's root: its link by forward kinematics at ``q`` (a camera on the
    robot), or the cell frame its link names (a camera fixed in the cell); None if its link is neither."""
    if model.has_frame(spec.link):
        return spec.optical_pose(model.frame_pose(q, spec.link))
    fixed = next((f.pose for f in cell.frames if f.name == spec.link), None) if cell is not None else None
    return None if fixed is None else spec.optical_pose(fixed)
