"""The mission tool's tests: they import its package (mppi_mission, drivers/mission) and the
bridge's (mppi_mavlink) as installed into the venv by tools/setup.sh."""
