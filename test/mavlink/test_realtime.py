"""Which of the bridge's threads run at SCHED_FIFO (mppi_mavlink/realtime.py): with
`realtime.priority` the latency path's threads take it once the bridge is built; its start,
its control requests and its map casting stay time-shared, below mppid's loop, so that a
bridge started or restarted on mppid's core cannot hold the loop off it. Where the OS refuses
the priority (no root, no CAP_SYS_NICE: not CI, which runs as root), the threads run
time-shared and say so."""
import gc
import logging
import os
import resource
import threading

import pytest

from mppi_mavlink import bridge as bridge_mod, control, realtime, settings as settings_mod

FIFO, OTHER = os.SCHED_FIFO, os.SCHED_OTHER
PERMITTED = os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= 85
AT_85 = (FIFO, 85) if PERMITTED else (OTHER, 0)   # what a thread asking for SCHED_FIFO 85 gets here


def policy_of(t: threading.Thread) -> tuple[int, int]:
    """(policy, priority) of a running thread, as the OS schedules it."""
    return os.sched_getscheduler(t.native_id), os.sched_getparam(t.native_id).sched_priority


def _bridge(tmp_path, *sets):
    s = settings_mod.load(None, ["mavlink.url=udpin:127.0.0.1:0", "vehicle.hover_thrust=0.4",
                                 f"control.socket={tmp_path / 'control.sock'}", *sets])
    return s, bridge_mod.Bridge(s, lcm_url="memq://")


def test_the_latency_path_runs_at_the_priority_and_the_rest_time_shared(tmp_path):
    s, b = _bridge(tmp_path, "realtime.priority=85")
    ctl = control.ControlServer(s["control"]["socket"], b.execute)
    try:
        b.start()
        ctl.start()
        assert {t.name: policy_of(t) for t in b.threads} == {"mavlink-rx": AT_85, "lcm": AT_85, "housekeeping": AT_85}
        assert policy_of(ctl.thread) == (OTHER, 0)
        assert policy_of(b.obstacles.thread) == (OTHER, 0)
        assert os.sched_getscheduler(0) == OTHER          # the thread that built and started it
        # What the start made is out of the collector's walks (a full one took 10-17 ms there).
        assert gc.get_freeze_count() > 10_000
    finally:
        ctl.close()
        b.close()
        gc.unfreeze()


def test_priority_zero_leaves_every_thread_time_shared(tmp_path):
    _, b = _bridge(tmp_path)
    try:
        b.start()
        assert {policy_of(t) for t in b.threads} == {(OTHER, 0)}
        assert gc.get_freeze_count() == 0
    finally:
        b.close()


def test_a_refused_priority_leaves_the_thread_time_shared_and_says_so(monkeypatch, caplog):
    """The OS refusing SCHED_FIFO (as for a user without CAP_SYS_NICE): the thread runs on,
    time-shared, and the bridge's log names the thread and the priority refused."""
    def refuse(*_):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    seen = {}
    with caplog.at_level(logging.WARNING, logger="mppi_mavlink"):
        t = realtime.thread(lambda: seen.update(policy=os.sched_getscheduler(0)), "rx", 85)
        t.start()
        t.join(5)
    assert seen == {"policy": OTHER}
    assert any("rx: SCHED_FIFO 85 refused" in r.getMessage() for r in caplog.records)


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
    assert seen == {"creator": AT_85, "helper": (OTHER, 0)}


@pytest.mark.parametrize("value", ["-1", "100", "85.5", "true"])
def test_a_bad_priority_names_the_field(value):
    with pytest.raises(settings_mod.SettingsError, match="realtime.priority"):
        settings_mod.load(None, [f"realtime.priority={value}"])
