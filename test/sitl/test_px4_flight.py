"""The PX4 SITL flight (flights/px4.py) without PX4: the command lines it builds (a fake
px4_sitl_sih build), the failsafe-flight options, and the score's pieces (px4_score.py:
PX4's map projection, the truth on the mission's clock, what PX4 did after a fault)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sitl_harness import cli, paths, px4_faults, px4_score
from sitl_harness.flights.base import FlightError, FlightSpec
from sitl_harness.flights.px4 import BASELINE, PARAMS, SENSOR_MOUNT, VEHICLE, Px4Flight, px4_params


def _fake_px4(tmp_path) -> Path:
    """A px4_sitl_sih build's layout: bin/px4 and etc/init.d-posix/rcS."""
    build = tmp_path / "px4_sitl_sih"
    (build / "etc" / "init.d-posix").mkdir(parents=True)
    (build / "etc" / "init.d-posix" / "rcS").write_text("#!/bin/sh\n")
    binary = build / "bin" / "px4"
    binary.parent.mkdir()
    binary.write_text("#!/bin/sh\nexit 0\n")
    binary.chmod(0o755)
    return binary


def test_px4_flight_needs_its_binary(tmp_path, monkeypatch):
    monkeypatch.delenv("MPPID_PX4_BIN", raising=False)
    with pytest.raises(FlightError, match="no PX4 SITL binary: build PX4 SITL with SIH"):
        Px4Flight.create(FlightSpec(scenario="hover", autopilot="px4"))
    lone = tmp_path / "px4"
    lone.write_text("")
    lone.chmod(0o755)
    with pytest.raises(FlightError, match="rcS not found"):
        Px4Flight.create(FlightSpec(scenario="hover", autopilot="px4", px4_bin=str(lone)))


def test_px4_parameters_come_from_the_argued_files():
    p = px4_params(PARAMS)
    assert p["COM_OF_LOSS_T"] == "0.5" and p["COM_OBL_RC_ACT"] == "5"
    assert set(px4_params(BASELINE)) == {"MPC_XY_VEL_P_ACC", "MPC_XY_VEL_I_ACC", "MPC_XY_P"}


def test_px4_offboard_baseline_commands(tmp_path):
    binary = _fake_px4(tmp_path)
    spec = FlightSpec(scenario="circle_3ms", seed=52, out=tmp_path / "out", controller="px4", realtime=True,
                      autopilot="px4", px4_bin=str(binary), autopilot_params=["COM_OBL_RC_ACT=0"])
    flight = Px4Flight.create(spec)
    flight.out.mkdir(parents=True)
    plan = flight.plan()
    cmds = plan.commands
    assert set(cmds) == {"logger", "sim", "recorder", "mission"}
    sim = cmds["sim"][cmds["sim"].index("env"):]
    assert "PX4_SIM_MODEL=sihsim_quadx" in sim and "PX4_PARAM_COM_OF_LOSS_T=0.5" in sim
    assert "PX4_PARAM_COM_OBL_RC_ACT=0" in sim and "PX4_PARAM_MPC_XY_P=2.0" in sim   # --autopilot-param wins
    assert "PX4_PARAM_MIS_TAKEOFF_ALT=2.0" in sim
    assert sim[-5:] == [str(binary.resolve()), "-d", "-w", str(flight.out / "px4"),
                        str(binary.resolve().parents[1] / "etc")]   # a fresh working folder every flight
    assert cmds["mission"][1:] == ["-m", "sitl_harness.px4_offboard", str(paths.MISSIONS / "circle_3ms.yaml"),
                                   "--url", "udpin:127.0.0.1:14540", "--seed", "52", "--out", str(flight.out)]
    assert cmds["recorder"][1:] == ["-m", "sitl_harness.px4_truth", "--out", str(flight.out)]
    assert plan.record["autopilot"] == "px4" and len(plan.record["load_avg_start"]) == 3


def test_px4_mppid_flight_with_a_link_cut(mppid_binary, tmp_path):
    binary = _fake_px4(tmp_path)
    spec = FlightSpec(scenario="circle_5ms", seed=51, out=tmp_path / "out", realtime=True, autopilot="px4",
                      px4_bin=str(binary), faults=["link_cut:3@5"])
    flight = Px4Flight.create(spec)
    flight.out.mkdir(parents=True)
    cmds = flight.plan().commands
    assert set(cmds) == {"logger", "sim", "recorder", "controller", "bridge", "mission", "relay"}
    ctrl = cmds["controller"]
    assert ctrl[ctrl.index("--vehicle") + 1] == str(VEHICLE)
    assert "mppi.u_max=[19.3,6.0,6.0,3.0]" in ctrl    # SIH's thrust (config/px4/mppid_overlay.yaml)
    bridge = cmds["bridge"]
    assert bridge[bridge.index("--config") + 1] == str(paths.ROOT / "config/bridge/px4_sitl.yaml")
    assert bridge[-2:] == ["--set", f"mavlink.url=udpin:127.0.0.1:{px4_faults.BRIDGE_PORT}"]
    assert cmds["relay"][-2:] == ["--cut-s", "3.0"]


def test_px4_sensed_survey_carries_the_camera_on_sihs_mount(mppid_binary, tmp_path):
    """The survey's sensors through PX4 see with SIH's airframe's camera mount (tilted up for its
    40-degree cruise, config/px4/sensor_mount.yaml); everything else is the mission's."""
    import yaml
    binary = _fake_px4(tmp_path)
    spec = FlightSpec(scenario="survey_forest_sensed", seed=1, out=tmp_path / "out", realtime=True,
                      autopilot="px4", px4_bin=str(binary))
    flight = Px4Flight.create(spec)
    flight.out.mkdir(parents=True)
    sensors = flight.plan().commands["sensors"]
    flown = yaml.safe_load(Path(sensors[sensors.index("--sensing") + 1]).read_text())["sensing"]
    mission = yaml.safe_load((paths.MISSIONS / "survey_forest_sensed.yaml").read_text())["sensing"]
    mount = yaml.safe_load(SENSOR_MOUNT.read_text())["sensing"]["depth_camera"]
    assert mount["pitch_deg"] < 0 and mission["depth_camera"]["pitch_deg"] == 0
    assert flown["depth_camera"] == {**mission["depth_camera"], **mount}
    assert "lidar" not in flown   # a mount adds no sensor the mission does not carry
    assert {k: v for k, v in flown.items() if k != "depth_camera"} == \
        {k: v for k, v in mission.items() if k != "depth_camera"}


@pytest.mark.parametrize("text,parsed", [("kill_mppid@5", ("kill_mppid", 5.0, 0.0)),
                                         ("link_cut:3@8.5", ("link_cut", 8.5, 3.0))])
def test_faults_parse(text, parsed):
    assert px4_faults.parse_fault(text) == parsed


@pytest.mark.parametrize("args,why", [
    (["--fault", "kill_mppid@5"], "for --autopilot px4"),
    (["--autopilot", "px4", "--fault", "link_cut@5"], "needs a duration"),
    (["--autopilot", "px4", "--fault", "explode@5"], "not one of"),
    (["--autopilot", "px4", "--controller", "px4", "--fault", "kill_mppid@5"], "fly mppid"),
])
def test_fault_options_are_checked(args, why, capsys):
    rc = cli.main(["run", "--scenario", "circle_3ms", "--realtime"] + args)
    assert rc == 2 and why in capsys.readouterr().err


def test_controllers_need_their_autopilot(capsys):
    assert cli.main(["run", "--scenario", "hover", "--realtime", "--controller", "px4"]) == 2
    assert "needs --autopilot px4" in capsys.readouterr().err
    assert cli.main(["run", "--scenario", "hover", "--autopilot", "px4", "--controller", "guided", "--realtime"]) == 2
    assert cli.main(["run", "--scenario", "hover", "--autopilot", "px4"]) == 2
    assert "add --realtime" in capsys.readouterr().err


def test_px4_projection_matches_its_geometry():
    """PX4's MapProjection on a sphere of 6 371 000 m: 1e-5 degree of latitude is 1.112 m north."""
    n, e = px4_score.project([473977432 + 100], [85455942], 473977432, 85455942)
    assert n[0] == pytest.approx(6_371_000 * math.radians(1e-5), rel=1e-6) and abs(e[0]) < 1e-9
    n, e = px4_score.project([473977432], [85455942 + 100], 473977432, 85455942)
    assert e[0] == pytest.approx(6_371_000 * math.radians(1e-5) * math.cos(math.radians(47.3977432)), rel=1e-5)


def _raw(out: Path, clock: str, rate: float = 0.99):
    """A flight's record: PX4's clock running `rate` as fast as ours, a climb to 2 m, a mode change."""
    rows = [{"event": "origin", "lat_e7": 473977432, "lon_e7": 85455942, "alt_mm": 489400, "wall_us": 0}]
    for k in range(200):
        wall = 1_000_000_000 + k * 20_000
        boot = int(k * 20_000 * rate)
        rows.append({"truth": 1, "boot_us": boot, "wall_us": wall + 2_000, "lat": 473977432 + k, "lon": 85455942,
                     "alt": 489400 + 10 * k, "v": [0, 0.5, 0.5], "q": [1, 0, 0, 0]})
        rows.append({"est": [0.0, 0.0, 0.01 * k], "boot_us": boot, "wall_us": wall + 2_500})
        if k == 100:
            rows.append({"event": "mode", "mode": "HOLD", "previous": "OFFBOARD", "wall_us": wall + 3_000})
    (out / "truth_raw.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (out / "mission.jsonl").write_text(json.dumps({"event": "mission", "clock": clock}) + "\n")


def test_the_truth_on_the_missions_clock(tmp_path):
    _raw(tmp_path, "state")
    lines = px4_score.convert(tmp_path)
    truth = [r for r in lines if "x" in r]
    assert len(truth) == 200 and truth[-1]["x"][2] == pytest.approx(1.99)
    assert truth[-1]["x"][1] == pytest.approx(199 * 6_371_000 * math.radians(1e-7), rel=1e-5)
    # mppid's clock: PX4's boot time mapped onto the wall clock, its 1 % drift followed
    late = np.array([r["mission_us"] - r["wall_us"] for r in truth[100:]])
    assert np.all(np.abs(late) < 3_000)
    assert truth[150]["mode"] == "HOLD" and truth[50]["mode"] == ""
    assert (tmp_path / "truth.jsonl").is_file()
    _raw(tmp_path, "boot")
    truth = [r for r in px4_score.convert(tmp_path) if "x" in r]
    assert [r["mission_us"] for r in truth[:3]] == [r["boot_us"] for r in truth[:3]]


def test_what_px4_did_after_a_fault(tmp_path):
    _raw(tmp_path, "state")
    lines = px4_score.convert(tmp_path)
    rep = px4_score.fault_report(lines, {"action": "gcs_hold", "wall_us": 1_000_000_000 + 90 * 20_000})
    assert rep["modes"] == [(0.2, "HOLD")]
    assert rep["alt_at_fault"] == pytest.approx(0.9) and rep["max_tilt_deg"] == 0.0
    assert rep["drift_m"] == pytest.approx(109 * 6_371_000 * math.radians(1e-7), abs=0.01)


def test_parallel_px4s_each_have_their_own_server_socket(tmp_path):
    """PX4's server socket is /tmp/px4-sock-<instance> whatever its working folder: the flight's
    PX4 (as root) runs with a /tmp of its own, so a campaign's PX4s at once never share it and
    the machine's /tmp keeps none of theirs."""
    import os
    import subprocess
    from sitl_harness.flights.px4 import px4_command

    if os.geteuid() != 0:
        if os.environ.get("CI"):
            pytest.fail("CI runs as root: the private /tmp's test must run there")
        pytest.skip("a private /tmp needs a mount namespace (root)")
    binary = _fake_px4(tmp_path)
    binary.write_text('#!/bin/sh\n[ -e /tmp/px4-sock-0 ] && exit 3\ntouch /tmp/px4-sock-0\nsleep 0.5\n'
                      'ls -A /tmp > "$3/seen"\n')  # $3: the work folder (-d -w WORK)
    before = Path("/tmp/px4-sock-0").exists()
    works = [tmp_path / f"w{i}" for i in range(2)]
    procs = []
    for w in works:
        w.mkdir()
        cmd = px4_command(binary, w, fifo=False, params={})
        procs.append(subprocess.Popen(cmd[:-2] + [str(w), str(w)]))  # the fake px4 writes into its work folder
    assert [p.wait(10) for p in procs] == [0, 0]     # 3: another PX4's socket was there
    for w in works:  # each socket in the flight's own folder; its work and build still reachable
        assert "px4-sock-0" in (w / "seen").read_text().split() and (w / "tmp" / "px4-sock-0").exists()
    assert Path("/tmp/px4-sock-0").exists() == before
