"""A sensed mission through ArduCopter SITL (flights/sensed.py), without ArduPilot: the referee's
truth on the sensors' bus (ap_truth.TruthPublisher: the bridge's frames, the states' clock, only
once the EKF's origin is known), the flight's extra processes and their buses, and the chain
truth -> mppid-sensors -> mppid-mapper -> local map with the real binaries."""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sitl_helpers import missing  # noqa: E402
from sitl_helpers import ROOT, fake_ardupilot  # noqa: E402
from sitl_harness import ap_truth, paths  # noqa: E402
from sitl_harness.flights.ardupilot import ArduPilotFlight  # noqa: E402
from sitl_harness.flights.base import FlightSpec, sensor_bus  # noqa: E402

mavlink = mavutil.mavlink
ORIGIN = (-353632621, 1491652374, 584.0)


def _recorder(tmp_path, publisher):
    r = ap_truth.Recorder.__new__(ap_truth.Recorder)  # no link: messages are handed in
    r.origin, r.f = ORIGIN, open(tmp_path / "truth.jsonl", "w")
    r.boot_us, r.est, r.truth, r.mode, r.armed = 0, None, None, "", False
    r.truth_out = publisher
    return r


def _sim_state(q, north_m=0.0, up_m=2.0, gyro=(0.0, 0.0, 0.0)):
    return mavlink.MAVLink_sim_state_message(
        *q, 0, 0, 0, 0, 0, 0, *gyro, 0, 0, ORIGIN[2] + up_m, 0, 0, 1.5, 0.5, -0.25,
        lat_int=ORIGIN[0] + round(north_m / ap_truth.M_PER_E7), lon_int=ORIGIN[1])


def test_the_referee_publishes_the_truth_in_the_bridges_frames_on_the_states_clock(tmp_path):
    import lcm
    from mppi_lcm import vehicle_state_t
    pub = ap_truth.TruthPublisher("memq://")
    got = []
    pub.lc.subscribe(ap_truth.TruthPublisher.CHANNEL, lambda ch, data: got.append(vehicle_state_t.decode(data)))
    r = _recorder(tmp_path, pub)
    facing_north = (1.0, 0.0, 0.0, 0.0)  # body FRD = NED: x forward along north
    r.handle(_sim_state(facing_north))
    r.handle(mavlink.MAVLink_local_position_ned_message(1000, 0, 0, -2.0, 0, 0, 0))
    pub.lc.handle_timeout(10)
    assert got == []  # no EKF origin yet: the frame may still move
    r.have_origin = True
    for k, delay_us in enumerate((4000, 1500, 3000)):
        r.handle(_sim_state(facing_north, north_m=1.0 * k, gyro=(0.1, 0.2, 0.3)))
        boot_ms = 2000 + 20 * k
        r.position_wall_us = boot_ms * 1000 + 10**12 + delay_us  # as received
        r.boot_us = boot_ms * 1000
        r._write_truth(True)
    while pub.lc.handle_timeout(10) > 0:
        pass
    assert len(got) == 3
    m = got[-1]
    assert (m.model, m.nx, m.n, m.vehicle_count) == (m.MODEL_QUADROTOR_RATE, 13, 13, 1)
    assert m.x[0] == pytest.approx(0.0, abs=1e-3) and m.x[1] == pytest.approx(2.0, abs=0.02)  # ENU: north is y
    assert m.x[2] == pytest.approx(2.0, abs=1e-3)
    assert list(m.x[3:6]) == pytest.approx([0.5, 1.5, 0.25])  # NED velocity (1.5, 0.5, -0.25) -> ENU
    w, qx, qy, qz = m.x[6:10]
    assert math.degrees(math.atan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))) == pytest.approx(90.0, abs=1e-3)
    assert list(m.x[10:13]) == pytest.approx([0.1, -0.2, -0.3])  # FRD -> FLU
    # Boot time + the smallest receipt delay so far (1.5 ms, the second's): one offset.
    assert [g.sample_utime for g in got] == [2_000_000 + 10**12 + 4000, 2_020_000 + 10**12 + 1500,
                                             2_040_000 + 10**12 + 1500]
    r.f.close()


def _plan(tmp_path, scenario):
    spec = FlightSpec(scenario=scenario, seed=51, out=tmp_path / scenario / "out", realtime=True, autopilot="ardupilot",
                      ardupilot_bin=str(fake_ardupilot(tmp_path / scenario)))
    flight = ArduPilotFlight.create(spec)
    flight.out.mkdir(parents=True)
    return spec, flight.plan().commands


def _tail(cmd, exe):
    return cmd[cmd.index(exe):] if exe in cmd else cmd[next(i for i, c in enumerate(cmd) if c.endswith(exe)):]


def test_a_sensed_mission_adds_the_sensors_and_the_mapper_and_keeps_the_trees_from_mppid(
        mppid_binary, tmp_path):
    if paths.find_binary("mppid-sensors") is None or paths.find_binary("mppid-mapper") is None:
        missing("mppid-sensors / mppid-mapper not built (cmake --build <build> --target mppid-sensors mppid-mapper)")
    spec, cmds = _plan(tmp_path, "rate_forest_sensed")
    bus = sensor_bus(spec.lcm_url)
    assert {"sensors", "mapper"} <= set(cmds)
    sensors = _tail(cmds["sensors"], "mppid-sensors")
    assert sensors[1:] == ["--sensing", str(paths.MISSIONS / "rate_forest_sensed.yaml"), "--seed", "51",
                           "--lcm-url", spec.lcm_url, "--sensor-lcm-url", bus, "--tree-height", "10",
                           "--stats", str(tmp_path / "rate_forest_sensed" / "out" / "sensors_stats.json")]
    mapper = _tail(cmds["mapper"], "mppid-mapper")
    assert mapper[mapper.index("--sensor-lcm-url") + 1] == bus
    assert cmds["recorder"][-2:] == ["--lcm-url", bus]  # the truth on the sensors' bus
    ctrl = cmds["controller"]
    assert ctrl[ctrl.index("--lcm-url") + 1].endswith("&recv_buf_size=4194304")  # 1 MB maps
    import yaml
    own = yaml.safe_load((paths.MISSIONS / "rate_forest_sensed.yaml").read_text())["mppid"]["set"]
    sets = [ctrl[i + 1] for i, c in enumerate(ctrl) if c == "--set"]
    assert sets[-len(own):] == own  # the mission's own settings, last
    logger = cmds["logger"]
    assert any("MPPI_DEPTH" in c and "MPPI_LOCAL_MAP" in c for c in logger)
    # The known-tree mission flies as it did: no sensors, no mapper, no truth on a bus.
    _, known = _plan(tmp_path, "rate_forest")
    assert not {"sensors", "mapper"} & set(known) and "--lcm-url" not in known["recorder"]


def test_the_sensed_missions_trees_are_the_known_missions_and_go_to_the_world():
    from mppi_mission import plan
    sensed = plan.load(ROOT / "config" / "missions" / "rate_forest_sensed.yaml")
    known = plan.load(ROOT / "config" / "missions" / "rate_forest.yaml")
    assert sensed.trees((0.3, -0.2), 57) == known.trees((0.3, -0.2), 57)
    assert sensed.trees_channel == "MPPI_WORLD" and known.trees_channel is None
    with pytest.raises(plan.PlanError, match="sensing"):
        plan.from_dict({"legs": [{"hold": {}}], "sensing": {"publish_obstacles": "no"}})


# ---- the chain with the real binaries -----------------------------------------------------
FEED = """
import sys, time
import lcm, mppi_lcm as t
lc, sensors = lcm.LCM(sys.argv[1]), lcm.LCM(sys.argv[2])  # the world on the flight's bus, the truth on the sensors'
def truth(sample_us):
    m = t.vehicle_state_t()
    m.utime = m.sample_utime = sample_us
    m.model, m.vehicle_count, m.nx, m.n = m.MODEL_QUADROTOR_RATE, 1, 13, 13
    m.x = [0.0, 0.0, 2.0, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0]  # facing +x, the forest's way
    return m.encode()
o = t.obstacles_t()
c = t.cylinder_t()
c.x, c.y, c.radius = 6.0, 0.0, 0.4
o.n, o.cylinders = 1, [c]
sensors.publish("SIM_TRUTH", truth(time.time_ns() // 1000))       # before the world: not cast
time.sleep(0.2)
lc.publish("MPPI_WORLD", o.encode())
time.sleep(0.1)
sensors.publish("SIM_TRUTH", truth(time.time_ns() // 1000 - 5_000_000))  # stale
t0 = time.time_ns() // 1000
for k in range(75):                    # 1.5 s of samples at 50 Hz, each sent once its time has come
    sample = t0 + 20_000 * k
    while time.time_ns() // 1000 < sample:
        time.sleep(0.002)
    lc.publish("MPPI_WORLD", o.encode())
    sensors.publish("SIM_TRUTH", truth(sample))
print('{"event": "done"}', flush=True)
time.sleep(60)
"""


def wait_log(path, text, timeout):
    """Waits (polling, up to `timeout` s) for `text` in the log at `path`, or fails."""
    deadline = time.monotonic() + timeout
    while text not in (path.read_text(errors="replace") if path.exists() else ""):
        assert time.monotonic() < deadline, f"{text!r} not in {path.name} after {timeout} s"
        time.sleep(0.05)


def test_truth_to_sensors_to_mapper_makes_a_map_of_the_tree_ahead(tmp_path):
    """A sensed flight's processes in a private network namespace (the harness's sandbox), fed
    as the referee and the mission tool feed them: mppid-sensors' frames reach mppid-mapper,
    whose map holds the tree ahead (sensed.jsonl names it), and the node counts the truths
    taken and refused."""
    import json
    from sitl_harness.sandbox import Sandbox
    sensors_exe, mapper_exe = paths.find_binary("mppid-sensors"), paths.find_binary("mppid-mapper")
    if sensors_exe is None or mapper_exe is None:
        missing("mppid-sensors / mppid-mapper not built (cmake --build <build> --target mppid-sensors mppid-mapper)")
    url = "udpm://239.255.76.67:7667?ttl=0"
    bus = sensor_bus(url)
    sb = Sandbox(tmp_path)
    sb.start_namespace()
    try:
        sb.spawn("sensors", [str(sensors_exe), "--sensing", str(ROOT / "config/missions/rate_forest_sensed.yaml"),
                             "--lcm-url", url, "--sensor-lcm-url", bus, "--stats", str(tmp_path / "sensors.json"),
                             "--max-truth-age", "1.0"])  # a busy machine's feeder is late, never 5 s
        sb.spawn("mapper", [str(mapper_exe), "--config", str(ROOT / "config/mapper/mapper.yaml"), "--lcm-url", url,
                            "--sensor-lcm-url", bus, "--stats", str(tmp_path / "mapper.json"),
                            "--sensed", str(tmp_path / "sensed.jsonl")])
        sb.wait_ready("sensors", 30.0)
        wait_log(tmp_path / "mapper.log", "cells of", 30.0)  # the mapper subscribed
        sb.spawn("feed", [sys.executable, "-c", FEED, url, bus])
        wait_log(tmp_path / "feed.log", '"done"', 60.0)
        # Each node, stopped, loses nothing: the sensors send the frames they captured, then
        # the mapper integrates what is on the bus.
        sb.terminate("sensors", 10.0)
        sb.terminate("mapper", 10.0)
    finally:
        sb.stop()
    logs = "".join((tmp_path / f"{n}.log").read_text() for n in ("sensors", "mapper", "feed"))
    stats = json.loads((tmp_path / "sensors.json").read_text())
    assert stats["truth"]["before_world"] == 1 and stats["truth"]["stale"] == 1, logs
    # Every truth of the 1.48 s of samples is taken (their ages here are the feeder's own
    # lateness, well inside --max-truth-age), and the camera's 30 Hz runs on the truths' sample
    # times: frames at 0, 1/30, ... 1.48 s, 45 of them, however busy the machine.
    assert stats["truth"]["taken"] == 75 and stats["trees"] == 1, stats
    frames = stats["sensors"]["depth_camera"]["frames"]
    assert frames == 45, stats
    mapped = json.loads((tmp_path / "mapper.json").read_text())
    assert mapped["frames"] == frames and mapped["maps"] > 0, mapped
    sensed = [json.loads(line) for line in (tmp_path / "sensed.jsonl").read_text().splitlines()]
    cols = [c for rec in sensed for c in rec["columns"]]
    assert cols and min(math.hypot(x - 6.0, y) for x, y in cols) < 0.5  # the tree's face, sensed
    assert all(math.hypot(x - 6.0, y) < 1.0 for x, y in cols)          # and nothing else
