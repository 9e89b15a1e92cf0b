"""Collision model and checks of a robot in its cell (coal through pinocchio's GeometryModel).

:mod:`scene` measures distances between the robot's links (the URDF's ``<collision>``), its
tools and held parts and the cell's boxes; :mod:`bodies` reads the cell's boxes and what a
gripper holds from the cell model; :mod:`robots` says which URDF and TCPs each robot uses.
:mod:`layout` holds what a scene state fixes (pairs, levers, work), :mod:`sweep` checks motions
by conservative advancement.  The dry run sweeps every motion with it (cell_runner/dry_run/collisions.py),
the Nextage simulator every motion as it starts (docs/application_xml.md, "What the check proves").
"""
from robot_bridges.collision.bodies import CellBox, HeldPart, cell_boxes, held_part
from robot_bridges.collision.robots import scene_for
from robot_bridges.collision.scene import DEFAULT_MARGIN, Body, CollisionScene, Contact

__all__ = ["DEFAULT_MARGIN", "Body", "CellBox", "CollisionScene", "Contact", "HeldPart", "cell_boxes", "held_part", "scene_for"]
