"""The wiring: what starts a cell and lets a person drive it.

The command line (``python -m execution_engine``), the embedded deployment and the per-node
processes (``ros2 run``, ``launch``), the dry run on the robot's simulator, the operator console,
the checks of a run's files and options.  It composes the layers below -- the function libraries
(``app_functions``), the engine and machines (``execution_engine``), the bridges and simulators
(``robot_bridges``) -- which never import each other or this package; only the operator station
(``operator_station``) sits above it.
"""
