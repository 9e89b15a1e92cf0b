"""Cameras as back ends: the simulator's renderer, ROS image topics, image files.

A camera gives an image (a numpy array) with its intrinsics; where it sits on the robot (the
hand-eye calibration, :class:`~robot_bridges.camera.spec.CameraSpec.mount`) and the robot's
forward kinematics at capture time place it in the world.  Processing is in
:mod:`core_functions.vision`; :mod:`robot_bridges.camera.vision` joins the two for the Vision state.
"""
