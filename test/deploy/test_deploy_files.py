"""The deployment's files (docs/deploy.md), from the source tree: the link profiles load and
say what their names promise, the units are valid and bound as mppid.target needs, and what
/etc/mppid holds by default builds a controller with the vehicle file beside it.
tools/package-test.sh tests the same files installed."""
from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "drivers" / "mavlink"))
from mppi_mavlink import settings  # noqa: E402

UNITS = ROOT / "drivers" / "systemd"
VEHICLE = ROOT / "config" / "deploy" / "vehicle.yaml"
LINKS = {"pi5_uart": "/dev/ttyAMA0", "jetson_uart": "/dev/ttyTHS1", "usb": "/dev/ttyACM0", "udp": None}
PROFILES = [ROOT / "config" / "bridge" / f"{ap}_{link}.yaml" for ap in ("px4", "ardupilot") for link in LINKS]
SERVICES = ("mppid-lcm-route.service", "mppid-recorder.service", "mppid.service", "mppid-mavlink-bridge.service")
MAPPER = "mppid-mapper.service"  # part of the target once enabled; not started by it unasked
REALSENSE = "mppid-realsense.service"  # the same


def build_dir() -> Path:
    return ROOT / os.environ.get("MPPID_BUILD_DIR", "build")


def unit(name: str) -> dict[str, list[str]]:
    """key -> values of a unit file (every section; a key given twice has two values)."""
    out: dict[str, list[str]] = {}
    for line in (UNITS / name).read_text().splitlines():
        if line and not line.startswith(("#", "[")) and "=" in line:
            k, v = line.split("=", 1)
            out.setdefault(k, []).append(v)
    return out


def words(u: dict, key: str) -> set[str]:
    return {w for v in u.get(key, []) for w in v.split()}


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.stem)
def test_link_profile_loads_and_names_its_port(path):
    s = settings.load(path, [f"vehicle.file={VEHICLE}"])
    autopilot, link = path.stem.split("_", 1)
    m = s["mavlink"]
    assert m["dialect"] == autopilot
    if LINKS[link]:
        assert m["url"] == LINKS[link]
    else:
        assert re.fullmatch(r"udpin:0\.0\.0\.0:145[45]0", m["url"]), m["url"]
    if link.endswith("uart"):
        assert m["baud"] == 921600  # PX4 SER_TEL2_BAUD 921600, ArduPilot SERIAL2_BAUD 921
    # ArduPilot sends no ODOMETRY: the bridge pairs ATTITUDE_QUATERNION and LOCAL_POSITION_NED.
    assert s["vehicle"]["state_source"] == ("split" if autopilot == "ardupilot" else "auto")
    assert s["vehicle"]["name"] == "my_quadrotor" and s["vehicle"]["file"] == str(VEHICLE)
    # The profile says what to set on the autopilot's side.
    text = path.read_text()
    assert ("MAV_" in text and "_MODE" in text) if autopilot == "px4" else "GUID_OPTIONS" in text


def test_a_wrong_key_in_a_profile_is_refused(tmp_path):
    bad = tmp_path / "p.yaml"
    bad.write_text(PROFILES[0].read_text() + "  buad: 57600\n")
    with pytest.raises(settings.SettingsError, match="buad"):
        settings.load(bad)


def test_the_target_starts_and_stops_every_service():
    t = unit("mppid.target")
    assert words(t, "Wants") == set(SERVICES) == words(t, "Also")
    assert words(t, "WantedBy") == {"multi-user.target"}
    assert {p.name for p in UNITS.glob("*.service")} == set(SERVICES) | {MAPPER, REALSENSE}
    for s in SERVICES + (MAPPER, REALSENSE):
        u = unit(s)
        assert words(u, "PartOf") == {"mppid.target"}, s
        assert words(u, "WantedBy") == {"mppid.target"}, s
        assert "network-online.target" not in words(u, "After") | words(u, "Wants"), f"{s}: a field has no network"
    for s in SERVICES[1:] + (MAPPER, REALSENSE):  # the bus needs the route first
        u = unit(s)
        assert "mppid-lcm-route.service" in words(u, "Requires") & words(u, "After"), s
    assert {"mppid.service", "mppid-mavlink-bridge.service"} <= words(unit("mppid-recorder.service"), "Before")


def exec_start(name: str) -> list[str]:
    return shlex.split(unit(name)["ExecStart"][0])


def option(argv: list[str], name: str) -> str:
    return argv[argv.index(name) + 1]


def test_mppid_and_the_bridge_fly_one_vehicle_file_from_etc():
    m, b = exec_start("mppid.service"), exec_start("mppid-mavlink-bridge.service")
    assert m[0] == "/usr/bin/mppid" and b[:2] == ["/usr/bin/mppid-mavlink-bridge", "run"]
    assert option(m, "--vehicle") == option(b, "--vehicle") == "/etc/mppid/vehicle.yaml"
    assert option(m, "--config") == "/etc/mppid/mppid.yaml"
    assert option(b, "--config") == "/etc/mppid/mavlink-bridge.yaml"
    conffiles = (ROOT / "cmake" / "debian" / "conffiles").read_text().split()
    assert sorted(conffiles) == sorted(["/etc/mppid/mppid.yaml", "/etc/mppid/vehicle.yaml",
                                        "/etc/mppid/mavlink-bridge.yaml", "/etc/mppid/mapper.yaml",
                                        "/etc/mppid/realsense.yaml"])


def test_the_bridge_takes_its_priority_once_started_above_mppids_loop():
    """Its latency path above mppid's loop (SCHED_FIFO 80, drivers/rt's default), within the
    unit's RLIMIT_RTPRIO; its start time-shared: no CPUSchedulingPolicy= (that would import
    pymavlink, numpy and lcm above the loop, a second held off a shared core)."""
    u, b = unit("mppid-mavlink-bridge.service"), exec_start("mppid-mavlink-bridge.service")
    assert "CPUSchedulingPolicy" not in u and "CPUSchedulingPriority" not in u
    assert 80 < int(option(b, "--realtime")) <= int(u["LimitRTPRIO"][0])


def test_the_mapper_is_enabled_on_its_own_and_maps_before_mppid_starts():
    t, u = unit("mppid.target"), unit(MAPPER)
    assert MAPPER not in words(t, "Wants") | words(t, "Also"), "a vehicle without a sensor runs no mapper"
    assert "mppid.service" in words(u, "Before") and "mppid-recorder.service" in words(u, "After")
    assert exec_start(MAPPER) == ["/usr/bin/mppid-mapper", "--config", "/etc/mppid/mapper.yaml"]
    assert "CPUSchedulingPolicy" not in u, "time-shared: below mppid's and the bridge's SCHED_FIFO"


def test_the_installed_mapper_settings_name_the_bus_and_run(tmp_path):
    """/etc/mppid/mapper.yaml (made by cmake/Install.cmake from config/mapper/mapper.yaml): the
    bus of the bridge's settings with a receive buffer for the frames, and the built mapper runs
    with it (memq://) until SIGTERM, then reports no frames."""
    cfg = build_dir() / "deploy" / "etc" / "mapper.yaml"
    text = cfg.read_text()
    url = settings.DEFAULTS["lcm"]["url"]
    assert f'\nlcm_url: "{url}&recv_buf_size=4194304"' in text
    assert '\nsensor_lcm_url: ""' in text
    mapper = build_dir() / "bin" / "mppid-mapper"
    p = subprocess.Popen([str(mapper), "--config", str(cfg), "--lcm-url", "memq://"], stderr=subprocess.PIPE, text=True)
    first = p.stderr.readline()  # printed once the settings loaded and the window is allocated
    p.send_signal(signal.SIGTERM)
    rest = p.communicate(timeout=30)[1]
    assert "128 x 128 x 32 cells of 0.25 m -> MPPI_LOCAL_MAP" in first, first + rest
    assert p.returncode == 0 and '"frames":0' in rest, rest


def test_the_camera_is_enabled_on_its_own_and_reads_its_installed_settings():
    t, u = unit("mppid.target"), unit(REALSENSE)
    assert REALSENSE not in words(t, "Wants") | words(t, "Also"), "a vehicle without the camera runs no driver"
    assert exec_start(REALSENSE) == ["/usr/bin/mppid-realsense", "--config", "/etc/mppid/realsense.yaml"]
    assert "CPUSchedulingPolicy" not in u, "time-shared: below mppid's and the bridge's SCHED_FIFO"
    assert "plugdev" in words(u, "SupplementaryGroups")  # the camera's USB device (udev rules)


def test_the_installed_camera_settings_name_the_bus_and_load():
    """/etc/mppid/realsense.yaml (made by cmake/Install.cmake from config/realsense/realsense.yaml):
    the bridge's bus, on which the states come and the frames go to the mapper's lcm_url."""
    sys.path.insert(0, str(ROOT / "drivers" / "realsense"))
    from mppi_realsense import settings as rs_settings
    cfg = build_dir() / "deploy" / "etc" / "realsense.yaml"
    s = rs_settings.load(str(cfg))
    url = settings.DEFAULTS["lcm"]["url"]
    assert s.lcm_url == url and s.sensor_lcm_url == "" and s.channel == "MPPI_DEPTH"
    mapper = (build_dir() / "deploy" / "etc" / "mapper.yaml").read_text()
    assert f'\nlcm_url: "{url}&recv_buf_size=4194304"' in mapper and "MPPI_DEPTH" in mapper


def test_route_and_recorder_use_the_group_of_the_settings_lcm_url():
    url = settings.DEFAULTS["lcm"]["url"]
    group = re.match(r"udpm://([0-9.]+):", url).group(1)
    routes = [shlex.split(v) for v in unit("mppid-lcm-route.service")["ExecStart"]]
    assert ["/usr/sbin/ip", "route", "replace", f"{group}/32", "dev", "lo"] in routes
    assert f"--lcm-url={url}" in exec_start("mppid-recorder.service")
    task = (ROOT / "config" / "tasks" / "quadrotor_rate_track.yaml").read_text()
    assert "lcm_url" not in task  # mppid's default, udpm://239.255.76.67:7667?ttl=0, is the bridge's


def test_units_verify(tmp_path):
    """systemd-analyze verify on every unit, the installed paths pointed at the build's."""
    mppid = build_dir() / "bin" / "mppid"
    logger = Path(sys.executable).parent / "lcm-logger"
    assert mppid.is_file(), f"{mppid} not built (tools/setup.sh)"
    swap = {"/usr/bin/mppid-mavlink-bridge": str(ROOT / "drivers" / "mavlink" / "mppid-mavlink-bridge"),
            "/usr/bin/mppid ": f"{mppid} ", "/usr/lib/mppid/python/bin/lcm-logger": str(logger),
            "/usr/bin/mppid-mapper": str(build_dir() / "bin" / "mppid-mapper"),
            "/usr/bin/mppid-realsense": str(Path(sys.executable).parent / "mppid-realsense")}
    for f in UNITS.iterdir():
        text = f.read_text()
        for a, b in swap.items():
            text = text.replace(a, b)
        (tmp_path / f.name).write_text(text)
    r = subprocess.run(["systemd-analyze", "verify"] + sorted(str(p) for p in tmp_path.iterdir()),
                       capture_output=True, text=True, cwd=tmp_path)
    ours = [line for line in (r.stdout + r.stderr).splitlines() if "mppid" in line]
    assert r.returncode == 0 and not ours, r.stdout + r.stderr


@pytest.mark.parametrize("task", ["etc", "quadrotor_rate_track_pi5"])
def test_the_default_settings_build_a_controller_with_the_vehicle(task):
    """/etc/mppid/mppid.yaml (the rate task with `vehicle: vehicle.yaml`, made by
    cmake/Install.cmake) and the Pi 5 task: mppid --self-test with the deployed vehicle file."""
    mppid = build_dir() / "bin" / "mppid"
    if task == "etc":
        cfg = build_dir() / "deploy" / "etc" / "mppid.yaml"
        text = cfg.read_text()
        assert "\ntask: quadrotor_rate_track\n" in text and "\nvehicle: vehicle.yaml\n" in text
    else:
        cfg = ROOT / "config" / "tasks" / f"{task}.yaml"
    r = subprocess.run([str(mppid), "--self-test", "--config", str(cfg), "--vehicle", str(VEHICLE)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "self-test passed: task quadrotor_rate_track" in r.stderr, r.stderr
    assert "vehicle my_quadrotor" in r.stderr


def test_self_test_fails_on_settings_that_cannot_fly(tmp_path):
    """The self-test is a real check: a vehicle whose model disagrees with the task is refused."""
    bad = tmp_path / "vehicle.yaml"
    bad.write_text(VEHICLE.read_text().replace("model: quadrotor_rate", "model: quadrotor"))
    r = subprocess.run([str(build_dir() / "bin" / "mppid"), "--self-test", "--config",
                        str(ROOT / "config" / "tasks" / "quadrotor_rate_track.yaml"), "--vehicle", str(bad)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "self-test passed" not in r.stderr


def test_every_command_block_of_the_first_flight_guide_says_where_it_runs():
    """docs/first-flight.md: each command block is tagged; the package stage runs the
    no-vehicle, stand-in and after-flight ones (test/deploy/package_flight.py)."""
    text = (ROOT / "docs" / "first-flight.md").read_text()
    fences = re.findall(r"^```(.*)$", text, flags=re.M)
    opening = fences[0::2]
    assert len(fences) % 2 == 0 and opening, "unbalanced fences"
    tags = {"no-vehicle", "stand-in", "after-flight", "board", "vehicle", "ground"}
    bad = [f for f in opening if not (f.startswith("sh ") and f[3:] in tags)]
    assert not bad, f"untagged or unknown blocks: {bad}"
    for runnable in ("no-vehicle", "stand-in", "after-flight"):
        assert f"sh {runnable}" in opening, runnable
