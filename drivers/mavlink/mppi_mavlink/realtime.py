"""Which of the bridge's threads run at SCHED_FIFO (`realtime.priority`, `run --realtime PRIO`).

The threads on the latency path take the priority, once the bridge is built: the MAVLink
receiver (states to mppid), the LCM thread (mppid's commands to the autopilot) and the
housekeeping tick (the stream timeout's stop setpoint, the failsafes). Their work is short
and bounded per message. Everything else stays time-shared, below mppid's loop (SCHED_FIFO 80):
the start (a second of importing pymavlink, numpy and lcm, which at SCHED_FIFO would hold mppid
off its core on a one-core budget), the control socket's requests (missions, parameters), the
map cast into OBSTACLE_DISTANCE, and the threads those start.

A latency thread is also where Python's collector runs when an allocation there trips it: a
full collection walks every object the imports made (~44,000; 10-17 ms on the 2-core VM), at
SCHED_FIFO above mppid's loop. `settle()` collects once at the start and freezes what is left,
so that later collections walk only what the bridge allocates while it runs.
"""
from __future__ import annotations

import gc
import logging
import os
import threading

log = logging.getLogger("mppi_mavlink")


def enter(priority: int) -> bool:
    """The calling thread at SCHED_FIFO `priority` (0: time-shared). False, and a warning,
    where the OS refuses it (no CAP_SYS_NICE, RLIMIT_RTPRIO below it): it runs on time-shared."""
    try:
        if priority:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        elif os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        return True
    except OSError as e:
        log.warning("%s: SCHED_FIFO %d refused (%s): time-shared", threading.current_thread().name, priority, e)
        return False


def settle() -> int:
    """Collect what the start left, then freeze the rest out of every later collection
    (gc.freeze): the number of objects frozen."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


def thread(target, name: str, priority: int = 0, args=()) -> threading.Thread:
    """A daemon thread that first takes `priority` (0: time-shared, whatever the thread that
    starts it runs at: a thread inherits its creator's policy)."""
    def run():
        enter(priority)
        target(*args)
    return threading.Thread(target=run, name=name, daemon=True)

