"""The mission tool through the bridge and the simulated ArduPilot, as the harness flies a
real ArduCopter SITL (issue 20): arm, the autopilot's own take-off (nothing forwarded while
it climbs), `offboard` with mppid holding where the take-off ended, a circle ramped up from
that hover, landing; mppid in real time, as in service."""
import json
import math
import subprocess

import pytest
import yaml

from mavtest import LCM_URL, PYTHON, ROOT
from mavchain import Chain
from mppi_mavlink import lcm_types
from mppi_mavlink.layout import QuadrotorRate as Q

pytestmark = pytest.mark.timeout(150)

# The last leg turns the vehicle to face 60 deg (ENU: counter-clockwise from east).
MISSION = {"name": "ci_circle", "task": "quadrotor_rate_track", "takeoff": 1.5,
           "legs": [{"hold": {"for": 2}}, {"circle": {"center": [-2.0, 0.0, 1.5], "radius": 2.0, "speed": 1.5}},
                    {"hold": {"for": 4, "yaw": 60}}]}


def test_mission_tool_flies_the_simulated_ardupilot_through_the_bridge(netns, procs, tmp_path):
    c = Chain(procs, tmp_path, autopilot="ardupilot", task="quadrotor_rate_track",
              vehicle_params=["GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"]).start()
    refs, yaws = [], []   # the references' yaw on the bus; the vehicle's heading in mppid's states
    mppi_lcm = lcm_types.import_mppi_lcm()
    c.lc.subscribe("MPPI_REFERENCE", lambda ch, data: refs.append(mppi_lcm.reference_t.decode(data).yaw))
    c.lc.subscribe("MPPI_STATE", lambda ch, data: yaws.append(heading(mppi_lcm.vehicle_state_t.decode(data).x)))
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(MISSION))
    env_path = f"{ROOT / 'drivers' / 'mission'}:{ROOT / 'drivers' / 'mavlink'}"
    p = subprocess.run([PYTHON, "-m", "mppi_mission", "fly", str(tmp_path / "m.yaml"), "--bridge", c.sock,
                        "--lcm-url", LCM_URL, "--out", str(tmp_path)], capture_output=True, text=True, timeout=120,
                       env={"PYTHONPATH": env_path, "PATH": "/usr/bin:/bin"}, cwd=ROOT)
    print(p.stdout[-3000:], p.stderr[-2000:])
    summary = json.loads((tmp_path / "mission_summary.json").read_text())
    assert p.returncode == 0 and summary["outcome"] == "done", summary
    circle = next(leg for leg in summary["legs"] if leg["kind"] == "circle")
    assert circle["rmse"] < 0.3, circle
    assert "RMS error" in p.stdout and "leg 2/3 circle" in p.stdout  # the progress it shows
    ev = c.events()
    assert any(e["event"] == "takeoff_complete" for e in ev)
    assert not any(e["event"] == "takeoff_taken_over" for e in ev), "mppid took over the autopilot's take-off"
    assert not any(e["event"] == "collision" for e in ev)
    assert [e["mode"] for e in ev if e["event"] == "mode"] == ["GUIDED", "LAND"]
    assert any(e["event"] == "landed" for e in ev)
    st = c.status()
    assert st["dropped_disengaged"] > 20 and st["setpoints_sent"] > 300 and not st["engaged"]
    c.stop_vehicle()
    # The yaw leg: its reference on the bus says 60 deg, and the vehicle turned to it (the
    # hold: within 5 deg for at least 0.2 s of states).
    assert refs and math.isclose(refs[-1], math.radians(60), abs_tol=1e-6), refs[-5:]
    turned = [y for y in yaws if abs(math.remainder(y - math.radians(60), math.tau)) < math.radians(5)]
    assert len(turned) >= 10, f"the vehicle never held 60 deg: last headings {[round(math.degrees(y)) for y in yaws[-10:]]}"


def heading(x):
    """ENU yaw (rad) of a rate quadrotor state's attitude quaternion."""
    w, qx, qy, qz = x[Q.QUAT]
    return math.atan2(2.0 * (w * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def test_mission_tool_refuses_a_mppid_running_another_task(netns, procs, tmp_path):
    """A forest mission against a mppid running the tracking task (its controller_status_t
    says which; stood in for here) would be a straight line through the trees: the tool refuses
    before anything is armed, naming both tasks."""
    from linktools import StandInController
    ctl = StandInController()  # status: task quadrotor_rate_track
    try:
        c = Chain(procs, tmp_path, autopilot="ardupilot", mppid=False,
                  vehicle_params=["GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"]).start()
        mission = {**MISSION, "task": "quadrotor_rate_forest"}
        (tmp_path / "m.yaml").write_text(yaml.safe_dump(mission))
        env_path = f"{ROOT / 'drivers' / 'mission'}:{ROOT / 'drivers' / 'mavlink'}"
        p = subprocess.run([PYTHON, "-m", "mppi_mission", "fly", str(tmp_path / "m.yaml"), "--bridge", c.sock,
                            "--lcm-url", LCM_URL, "--out", str(tmp_path)], capture_output=True, text=True,
                           timeout=60, env={"PYTHONPATH": env_path, "PATH": "/usr/bin:/bin"}, cwd=ROOT)
        summary = json.loads((tmp_path / "mission_summary.json").read_text())
        assert p.returncode == 1, p.stdout + p.stderr
        assert "'quadrotor_rate_track'" in summary["outcome"] and "'quadrotor_rate_forest'" in summary["outcome"]
        assert not c.events("armed") and not c.status()["armed"]
        c.stop_vehicle()
    finally:
        ctl.close()
