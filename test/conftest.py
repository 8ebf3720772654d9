"""Every Python test: flights take turns on this machine's cores (tools/sitl_harness/turns.py;
a flight started by `tools/sitl run` or a MAVLink test's chain waits for the one flying). The
suite runs on two workers (tools/test.sh), and two flights' SCHED_FIFO processes on the same
two cores at once starve each other."""
import os

os.environ.setdefault("MPPID_REALTIME_LOCK", f"/tmp/mppid-realtime-{os.getuid()}.lock")
