"""Vision on images: camera model, hole/disc detection, sharpness and pixel -> 3D geometry.

Everything here is pure image processing and geometry on numpy arrays (OpenCV underneath), with
no knowledge of where an image came from: cameras (simulator renderer, ROS image topics, files)
are back ends in ``robot_bridges``.  The Vision state of every back end and the command
``python -m execution_engine vision detect`` call the same functions (docs/vision.md).
"""
