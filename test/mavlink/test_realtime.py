"""Which of the bridge's threads run at SCHED_FIFO (mppi_mavlink/realtime.py): with
`realtime.priority` the latency path's threads take it once the bridge is built; its start,
its control requests and its map casting stay time-shared, below mppid's loop, so that a
bridge started or restarted on mppid's core cannot hold the loop off it."""
import gc
import os
import threading

import pytest

from mppi_mavlink import bridge as bridge_mod, control, realtime, settings as settings_mod

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root (CAP_SYS_NICE), as CI runs")
FIFO, OTHER = os.SCHED_FIFO, os.SCHED_OTHER


def test_the_latency_path_runs_at_the_priority_and_the_rest_time_shared(tmp_path):
    s = settings_mod.load(None, ["realtime.priority=85", "mavlink.url=udpin:127.0.0.1:0",
                                 "vehicle.hover_thrust=0.4", f"control.socket={tmp_path / 'control.sock'}"])
    b = bridge_mod.Bridge(s, lcm_url="memq://")
    ctl = control.ControlServer(s["control"]["socket"], b.execute)
    try:
        b.start()
        ctl.start()
        assert {t.name: realtime.policy_of(t) for t in b.threads} == {
            "mavlink-rx": (FIFO, 85), "lcm": (FIFO, 85), "housekeeping": (FIFO, 85)}
        assert realtime.policy_of(ctl.thread) == (OTHER, 0)
        assert realtime.policy_of(b.obstacles.thread) == (OTHER, 0)
        assert os.sched_getscheduler(0) == OTHER          # the thread that built and started it
        # What the start made is out of the collector's walks (a full one took 10-17 ms there).
        assert gc.get_freeze_count() > 10_000
    finally:
        ctl.close()
        b.close()
        gc.unfreeze()


def test_priority_zero_leaves_every_thread_time_shared(tmp_path):
    s = settings_mod.load(None, ["mavlink.url=udpin:127.0.0.1:0", "vehicle.hover_thrust=0.4",
                                 f"control.socket={tmp_path / 'control.sock'}"])
    b = bridge_mod.Bridge(s, lcm_url="memq://")
    try:
        b.start()
        assert {realtime.policy_of(t) for t in b.threads} == {(OTHER, 0)}
    finally:
        b.close()


def test_a_thread_started_from_the_latency_path_is_time_shared():
    """A FIFO thread starting slow work (the link-up's parameter reads, a hand-back): the new
    thread drops to time-shared instead of inheriting the creator's SCHED_FIFO."""
    seen = {}
    done = threading.Event()

    def slow_work():
        seen["helper"] = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        done.set()

    def latency_path():
        seen["creator"] = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        realtime.thread(slow_work, "helper").start()

    realtime.thread(latency_path, "rx", 85).start()
    assert done.wait(5)
    assert seen == {"creator": (FIFO, 85), "helper": (OTHER, 0)}


@pytest.mark.parametrize("value", ["-1", "100", "85.5", "true"])
def test_a_bad_priority_names_the_field(value):
    with pytest.raises(settings_mod.SettingsError, match="realtime.priority"):
        settings_mod.load(None, [f"realtime.priority={value}"])
