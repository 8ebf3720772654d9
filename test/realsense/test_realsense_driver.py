"""mppid-realsense (drivers/realsense, docs/sensing.md "A RealSense camera") with no camera: its
settings refused field by field, the cloud's geometry and refusals, and a synthetic wall recorded
through librealsense's software device into a file, played back through the driver into
mppid-mapper, whose map holds the wall where it stands."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sitl_harness import paths

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "realsense" / "realsense.yaml"
FEED = Path(__file__).resolve().parent / "vehicle_feed.py"


def missing(why: str):
    """Skip on a developer's partial set-up; in CI, which installs everything, fail."""
    if os.environ.get("CI"):
        pytest.fail(why + " (CI installs everything: this is a set-up problem)")
    pytest.skip(why)


def run_driver(*args, timeout=30.0):
    return subprocess.run([sys.executable, "-m", "mppi_realsense", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


@pytest.mark.parametrize("assignment, field", [
    ("decimation=9", "decimation"),
    ("range.min=12", "range.min"),
    ("range.max=-1", "range.max"),
    ("mount.offset=[0.1,0]", "mount.offset"),
    ("mount.rotation_deg=[0,.nan,0]", "mount.rotation_deg"),
    ("timestamps=gps", "timestamps"),
    ("stream.fps=0", "stream.fps"),
    ("max_points=0", "max_points"),
    ("state.max_age=true", "state.max_age"),
    ("range.far=3", "range.far"),
])
def test_a_bad_setting_is_refused_naming_the_field(assignment, field):
    from mppi_realsense import settings
    with pytest.raises(settings.SettingsError) as e:
        settings.load(str(CONFIG), [assignment])
    assert str(e.value).startswith(f"{field}: "), e.value


def test_a_bad_settings_file_exits_non_zero_naming_the_field(tmp_path):
    bad = tmp_path / "realsense.yaml"
    bad.write_text(CONFIG.read_text().replace("decimation: 4", "decimation: four"))
    r = run_driver("--config", str(bad))
    assert r.returncode == 2 and r.stderr.startswith("mppid-realsense: decimation: must be an integer"), r
    r = run_driver("--config", str(CONFIG), "--set", "range.min=12")
    assert r.returncode == 2 and r.stderr.startswith("mppid-realsense: range.min: must be below range.max"), r


def test_without_pyrealsense2_it_exits_1_saying_how_to_install_it(monkeypatch, capsys):
    """The package does not carry pyrealsense2 (docs/deploy.md): the program says what to do."""
    from mppi_realsense.__main__ import main
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)  # import fails as if not installed
    assert main(["--config", str(CONFIG), "--lcm-url", "memq://"]) == 1
    err = capsys.readouterr().err
    pin = next(line for line in (ROOT / "requirements.txt").read_text().splitlines() if line.startswith("pyrealsense2=="))
    assert err.startswith(f"mppid-realsense: pyrealsense2 is not installed: pip install {pin} "), err  # the tested one


def test_the_shipped_settings_are_the_defaults():
    from mppi_realsense import settings
    assert settings.load(str(CONFIG)) == settings.load(None)


def test_a_cloud_drops_holes_and_near_returns_and_turns_far_ones_into_misses():
    from mppi_realsense.cloud import CloudBuilder
    b = CloudBuilder(min_range=0.2, max_range=10.0, max_points=100)
    # optical frame: x right, y down, z forward
    v = np.array([[0, 0, 0], [0.0, 0.0, 0.1], [1.0, -0.5, 4.0], [0.0, 0.0, 30.0]], dtype=np.float32)
    x, y, z, hit = b.build(v)
    assert len(x) == 2  # the hole and the 0.1-m return are not sent
    np.testing.assert_allclose([x[0], y[0], z[0]], [4.0, -1.0, 0.5])  # x forward, y left, z up
    assert hit.tolist() == [1, 0]
    np.testing.assert_allclose([x[1], y[1], z[1]], [10.0, 0.0, 0.0], atol=1e-5)  # a miss at max_range


def test_a_frame_with_nan_or_no_depth_is_refused_and_counted():
    from mppi_realsense.cloud import CloudBuilder
    b = CloudBuilder(min_range=0.2, max_range=10.0, max_points=100)
    assert b.build(np.array([[0.0, 0.0, 2.0], [np.nan, 0.0, 3.0]], dtype=np.float32)) is None
    assert b.build(np.zeros((50, 3), dtype=np.float32)) is None
    assert b.build(np.array([[0.0, 0.0, 0.05]], dtype=np.float32)) is None  # nothing in range
    assert b.rejected == {"not_finite": 1, "no_depth": 2}


def test_the_point_budget_thins_evenly():
    from mppi_realsense.cloud import CloudBuilder
    b = CloudBuilder(min_range=0.2, max_range=10.0, max_points=100)
    v = np.stack([np.linspace(-1, 1, 1000), np.zeros(1000), np.full(1000, 3.0)], axis=1).astype(np.float32)
    x, y, z, hit = b.build(v)
    assert len(x) == 100 and b.points_cut == 900
    assert y.max() == pytest.approx(1.0) and y.min() == pytest.approx(-1.0)  # both edges kept


def test_the_mounting_places_and_turns_the_sensor():
    from mppi_realsense.cloud import mount_quat, quat_rotate, sensor_pose
    yaw = math.radians(90.0)
    body_q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))  # facing north (ENU +y)
    p, q = sensor_pose((1.0, 2.0, 3.0), body_q, (0.2, 0.0, 0.1), mount_quat((0.0, 30.0, 0.0)))
    np.testing.assert_allclose(p, [1.0, 2.2, 3.1], atol=1e-12)
    axis = quat_rotate(q, (1.0, 0.0, 0.0))  # the optical axis: north, 30 degrees down
    np.testing.assert_allclose(axis, [0.0, math.cos(math.radians(30)), -math.sin(math.radians(30))], atol=1e-12)
    left = quat_rotate(q, (0.0, 1.0, 0.0))  # the sensor's y: the vehicle's left, west
    np.testing.assert_allclose(left, [-1.0, 0.0, 0.0], atol=1e-12)


def wait_exit(sb, name, timeout):
    deadline = time.monotonic() + timeout
    while sb.returncode(name) is None:
        assert time.monotonic() < deadline, f"{name} still running after {timeout} s"
        time.sleep(0.05)
    return sb.returncode(name)


def wait_log(path, text, timeout):
    deadline = time.monotonic() + timeout
    while text not in (path.read_text(errors="replace") if path.exists() else ""):
        assert time.monotonic() < deadline, f"{text!r} not in {path.name} after {timeout} s"
        time.sleep(0.05)


# The scene and the vehicle: a wall 4 m ahead of the camera, from 0.5 m left of the optical axis
# to 1.5 m right of it; the vehicle at (1, 2, 2) facing north (yaw 90 deg), the camera 0.2 m
# ahead of its centre and 0.1 m up. So the wall stands at y = 2 + 0.2 + 4 = 6.2 and, the
# camera's right being east, from x = 0.5 to 2.5.
WALL = {"distance": 4.0, "left": -0.5, "right": 1.5, "frames": 10, "empty": 1}
VEHICLE = (1.0, 2.0, 2.0, 90.0)
MOUNT = ["--set", "mount.offset=[0.2,0,0.1]", "--set", "mount.rotation_deg=[0,0,0]"]


def test_a_recorded_wall_played_back_lands_in_the_map_where_it_stands(tmp_path):
    """Software device -> recording -> mppid-realsense --bag -> point_cloud_t -> mppid-mapper,
    in a private network namespace: every recorded frame read, the empty one refused, the
    clouds decimated, within the range limits and the point budget, placed by the vehicle's
    state and the mounting; the wall's columns in the map at its distance and its extent."""
    try:
        from mppi_realsense import synthetic
        synthetic.import_rs()
    except RuntimeError as e:
        missing(str(e))
    mapper = paths.find_binary("mppid-mapper")
    if mapper is None:
        missing("mppid-mapper not built (cmake --build <build> --target mppid-mapper)")
    from sitl_harness.sandbox import Sandbox
    rec = tmp_path / "wall.db3"
    info = synthetic.record(rec, **WALL)  # 424 x 240 at 30 fps
    assert rec.stat().st_size < 1_000_000
    url = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"
    bus = "udpm://239.255.76.67:7668?ttl=0&recv_buf_size=4194304"
    sb = Sandbox(tmp_path)
    sb.start_namespace()
    try:
        sb.spawn("mapper", [mapper, "--config", ROOT / "config/mapper/mapper.yaml", "--lcm-url", url,
                            "--sensor-lcm-url", bus, "--stats", tmp_path / "mapper.json",
                            "--sensed", tmp_path / "sensed.jsonl"])
        sb.spawn("feed", [sys.executable, FEED, url, bus, tmp_path / "clouds.json", *VEHICLE])
        wait_log(tmp_path / "mapper.log", "cells of", 30.0)  # the mapper subscribed
        sb.wait_ready("feed", 30.0)
        # Host timestamps: the recording's own are from its time, not this flight's. The
        # state's age bound is wide: the vehicle stands still, and a busy machine is late.
        sb.spawn("realsense", [sys.executable, "-m", "mppi_realsense", "--config", CONFIG, "--bag", rec,
                               "--lcm-url", url, "--sensor-lcm-url", bus, "--stats", tmp_path / "realsense.json",
                               "--set", "decimation=2", "--set", "max_points=6000", "--set", "timestamps=host",
                               "--set", "state.max_age=10", *MOUNT])
        rc = wait_exit(sb, "realsense", 60.0)
        sb.terminate("feed", 10.0)
        sb.terminate("mapper", 10.0)
    finally:
        sb.stop()
    logs = "".join((tmp_path / f"{n}.log").read_text() for n in ("realsense", "mapper", "feed"))
    assert rc == 0, logs
    st = json.loads((tmp_path / "realsense.json").read_text())
    # Every recorded frame read; the one with no depth refused; none without a state.
    assert st["frames"] == WALL["frames"] + WALL["empty"], st
    assert st["published"] == WALL["frames"] and st["rejected"] == {"no_depth": 1, "no_state": 0}, st
    assert (st["width"], st["height"]) == (info["width"] // 2, info["height"] // 2), st  # decimation 2
    # 212 x 120 pixels less the near strip's 4 rows: more than the budget, thinned to it.
    assert st["points_cut"] == WALL["frames"] * (212 * 116 - 6000), st

    clouds = json.loads((tmp_path / "clouds.json").read_text())
    assert [c["seq"] for c in clouds] == list(range(WALL["frames"])), logs
    for c in clouds:
        assert c["finite"] and c["n"] == 6000 and c["sensor"] == 1, c
        assert c["range_min"] >= 0.2 and c["range_max"] <= 10.0 + 1e-4, c  # the near strip dropped, far cut
        assert 0 < c["hits"] < c["n"], c  # the wall's returns and the background's misses
        # The wall's returns: 4 m ahead, from 1.5 m right (y = -1.5) to 0.5 m left, within a pixel.
        assert c["hit_x"] == pytest.approx([4.0, 4.0], abs=0.01), c
        assert c["hit_y"][0] == pytest.approx(-1.5, abs=0.05) and c["hit_y"][1] == pytest.approx(0.5, abs=0.05), c
        np.testing.assert_allclose(c["position"], [1.0, 2.2, 2.1], atol=1e-5)
        np.testing.assert_allclose(c["orientation"], [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)], atol=1e-6)

    mapped = json.loads((tmp_path / "mapper.json").read_text())
    assert mapped["frames"] == WALL["frames"] and mapped["maps"] > 0, mapped
    cols = [c for line in (tmp_path / "sensed.jsonl").read_text().splitlines() for c in json.loads(line)["columns"]]
    assert cols, mapped
    xs, ys = [x for x, _ in cols], [y for _, y in cols]
    cell = 0.25
    assert all(abs(y - 6.2) <= cell for y in ys), sorted(set(ys))  # the wall's distance, and nothing else
    assert min(xs) == pytest.approx(0.5, abs=cell) and max(xs) == pytest.approx(2.5, abs=cell), (min(xs), max(xs))


def rate_state(sample_utime, x=0.0, q=(1.0, 0.0, 0.0, 0.0), vehicles=1):
    import mppi_lcm
    s = mppi_lcm.vehicle_state_t()
    s.model, s.vehicle_count, s.nx, s.n = s.MODEL_QUADROTOR_RATE, vehicles, 13, 13 * vehicles
    s.sample_utime = sample_utime
    s.x = [x, 0.0, 1.0, 0.0, 0.0, 0.0, *q, 0.0, 0.0, 0.5] * vehicles
    return s


def test_a_frame_takes_the_state_sampled_nearest_its_time_within_max_age():
    import mppi_lcm
    from mppi_realsense.states import StateHistory
    h = StateHistory(mppi_lcm.vehicle_state_t.MODEL_QUADROTOR_RATE, vehicle=0, max_age_s=0.05)
    for i, t in enumerate((1_000_000, 1_020_000, 1_040_000)):
        assert h.on_state(rate_state(t, x=float(i)))
    assert h.pose_at(1_029_000)[0][0] == 1.0 and h.pose_at(1_031_000)[0][0] == 2.0
    assert h.pose_at(1_090_000)[0][0] == 2.0 and h.pose_at(1_090_001) is None  # 50 ms after the newest
    assert h.pose_at(949_999) is None
    assert not h.on_state(rate_state(1_040_000))  # not newer
    assert not h.on_state(rate_state(1_050_000, q=(0.5, 0.0, 0.0, 0.0)))  # not a unit quaternion
    bad = rate_state(1_060_000)
    bad.model = bad.MODEL_QUADROTOR
    assert not h.on_state(bad)
    assert h.refused == {"out_of_order": 1, "not_finite": 1, "layout": 1} and h.taken == 3


def test_a_frame_is_stamped_on_the_host_clock_its_own_time_or_its_arrival():
    import mppi_lcm
    from mppi_realsense import settings
    from mppi_realsense.camera import DepthFrame
    from mppi_realsense.driver import Driver
    d = Driver(settings.load(str(CONFIG)), mppi_lcm, lambda ch, data: None)
    own = DepthFrame(None, 1_795_000_000_123.5, True, 212, 120, 1)  # librealsense's global time [ms]
    assert d.frame_utime(own) == 1_795_000_000_123_500
    before = time.time_ns() // 1000
    hw = DepthFrame(None, 42.0, False, 212, 120, 2)  # the camera's own clock: its arrival instead
    assert before <= d.frame_utime(hw) <= time.time_ns() // 1000 and d.n["host_stamped"] == 1
    d = Driver(settings.load(str(CONFIG), ["timestamps=host"]), mppi_lcm, lambda ch, data: None)
    assert before <= d.frame_utime(own) <= time.time_ns() // 1000 and d.n["host_stamped"] == 0


def software_camera(rs, modes):
    """A software device with a depth sensor offering `modes` [(width, height)] at 30 fps, as a
    D4xx's stereo module offers its depth modes; returns the device, its sensor, the profiles."""
    dev = rs.software_device()
    dev.register_info(rs.camera_info.serial_number, "123456")
    sensor = dev.add_sensor("Stereo Module")
    profiles = []
    for uid, (w, h) in enumerate(modes):
        intr = rs.intrinsics()
        intr.width, intr.height, intr.ppx, intr.ppy, intr.fx, intr.fy = w, h, (w - 1) / 2, (h - 1) / 2, w / 2, w / 2
        intr.model, intr.coeffs = rs.distortion.brown_conrady, [0.0] * 5
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid = rs.stream.depth, 0, uid
        vs.width, vs.height, vs.fps, vs.bpp, vs.fmt, vs.intrinsics = w, h, 30, 2, rs.format.z16, intr
        profiles.append(sensor.add_video_stream(vs).as_video_stream_profile())
    sensor.add_read_only_option(rs.option.depth_units, 0.001)
    return dev, sensor, profiles


def test_a_live_camera_streams_the_asked_mode_decimated_and_stamped_on_the_host_clock():
    """The live path (no recording) on a software device standing in for the camera: the
    settings' depth mode chosen among the sensor's, an unknown one refused naming them, frames
    pushed with librealsense's global time deprojected, decimated and kept on the host clock."""
    from mppi_realsense import settings
    from mppi_realsense.camera import Camera
    try:
        from mppi_realsense.camera import import_rs
        rs = import_rs()
    except RuntimeError as e:
        missing(str(e))
    dev, sensor, profiles = software_camera(rs, [(424, 240), (848, 480)])
    with pytest.raises(RuntimeError, match=r"^stream: 640x480@30 is not one of the camera's depth modes "
                                           r"\(424x240@30, 848x480@30\)"):
        Camera(settings.load(str(CONFIG), ["stream.width=640"]), device=dev)
    cam = Camera(settings.load(str(CONFIG), ["stream.width=424", "stream.height=240", "decimation=2"]), device=dev)
    assert (cam.profile.width(), cam.profile.height()) == (424, 240)
    got = []
    cam.start(got.append)
    stamps = [time.time() * 1000.0 + k for k in range(3)]
    for i, ts in enumerate(stamps):
        f = rs.software_video_frame()
        f.pixels = np.full((240, 424), 2500, dtype=np.uint16).tobytes()
        f.bpp, f.stride, f.timestamp, f.domain = 2, 2 * 424, ts, rs.timestamp_domain.global_time
        f.frame_number, f.profile = i + 1, profiles[0]
        sensor.on_video_frame(f)
    deadline = time.monotonic() + 30.0
    while len(got) < 3 and time.monotonic() < deadline:
        time.sleep(0.01)
    cam.stop()
    assert [g.timestamp_ms for g in got] == pytest.approx(stamps, abs=1e-3) and all(g.host_clock for g in got)
    assert all((g.width, g.height) == (212, 120) for g in got)
    z = got[0].vertices[:, 2]
    assert len(z) == 212 * 120 and z == pytest.approx(2.5, abs=1e-3)  # a flat scene 2.5 m ahead
