"""Every Python test: real-time flights take turns on this machine's cores
(tools/sitl_harness/turns.py; a flight started by `tools/sitl run --realtime` or a test's
real-time mppid waits for the one flying). The suite runs on two workers (tools/test.sh), and
two SCHED_FIFO daemons flying on the same two cores at once starve both simulators."""
import os

os.environ.setdefault("MPPID_REALTIME_LOCK", f"/tmp/mppid-realtime-{os.getuid()}.lock")
