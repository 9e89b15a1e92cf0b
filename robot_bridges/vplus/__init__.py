"""Adept V+ back end: AdeptServer wire codec, asyncio client, simulator, kinematics and the bridge back end.

See docs/vplus.md.  Nothing here imports rclpy; the ROS 2 node (``node.py``) wraps the back end.
"""
