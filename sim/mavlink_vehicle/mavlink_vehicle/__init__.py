"""A simulated autopilot on MAVLink for bridge tests. See ../README.md."""
