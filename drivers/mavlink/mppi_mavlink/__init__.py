"""mppi_mavlink: the bridge between mppid (LCM) and an autopilot (MAVLink). See ../README.md."""
