"""The flight recorder: every topic of a run as MCAP (ROS 2 schemas, CDR), written off the control path."""
