"""Core functions: the primitives (the robot API), the robots, geometry and the function catalog."""
