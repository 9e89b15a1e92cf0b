"""The bridges' ``ros2 run`` executables: one module per back end declaring its node parameters.

A bridge process composes a back end (``robot_bridges``) with the node process of
:mod:`cell_runner.ros_main`, so its entry point belongs to the wiring, not to the bridge.
"""
