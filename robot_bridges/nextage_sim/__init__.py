"""Kawada Nextage Open kinematic simulator back end (docs/nextage_sim.md).

``backend.NextageSimBackend`` is the :class:`~robot_bridges.backend.RobotBackend`; ``model``
(pinocchio FK/IK on ``urdf/nextage_open.urdf``), ``trajectory``, ``planning``, ``jobs``, ``checks``,
``hands``, ``vision`` and ``faults`` are its parts.  Nothing is imported here, so that choosing another back end never
loads pinocchio.
"""
