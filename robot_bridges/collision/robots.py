"""Which URDF and which TCPs a robot's collision model uses.

The URDFs are the ones the bridges publish as ``robot_description`` (their ``<collision>``
elements are the collision model); the TCPs are where each bridge puts an arm's tool point, so
the held part sits where the skills hold it.
"""
from __future__ import annotations

import math
from pathlib import Path

from core_functions.geometry import Pose
from core_functions.robots import ADEPT_VIPER_S850, KUKA_KR, NEXTAGE_OPEN, RobotModel
from robot_bridges.collision.scene import DEFAULT_MARGIN, ArmTcp, CollisionScene

_ROOT = Path(__file__).resolve().parents[1]
#: The Nextage's TCP: the wrist flange, z out of the hand (robot_bridges.nextage_sim.backend.HAND_TOOL).
NEXTAGE_HAND = Pose.from_xyz_rpy(0.0, 0.0, 0.0, 0.0, -math.pi / 2, 0.0)
MODELS: dict[str, tuple[Path, dict[str, ArmTcp]]] = {
    NEXTAGE_OPEN.name: (
        _ROOT / "nextage_sim" / "urdf" / "nextage_open.urdf",
        {"left_arm": ArmTcp("LARM_JOINT5_Link", NEXTAGE_HAND), "right_arm": ArmTcp("RARM_JOINT5_Link", NEXTAGE_HAND)},
    ),
    ADEPT_VIPER_S850.name: (_ROOT / "vplus" / "urdf" / "adept_viper_s850.urdf", {"arm": ArmTcp("flange")}),
    KUKA_KR.name: (_ROOT / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf", {"arm": ArmTcp("tool0")}),
}


def scene_for(robot: RobotModel, margin: float = DEFAULT_MARGIN) -> CollisionScene:
    """The collision model of ``robot`` (KeyError for a robot without one)."""
    urdf, tcps = MODELS[robot.name]
    return CollisionScene(robot, urdf, tcps, margin)
