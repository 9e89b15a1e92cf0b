"""The ``ros2-control`` back end: any robot whose ROS 2 driver serves control_msgs/action/FollowJointTrajectory.

The robot known by its URDF (``/robot_description``), driven through its controllers' actions, watched
through ``/joint_states``.  See docs/ros2.md, "The ros2-control back end".  Nothing here imports rclpy:
the graph is reached through the transport port (Cyclone DDS by default, rclpy with ``transport=ros``).
"""
