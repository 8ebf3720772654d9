"""A survey uploaded to the autopilot (config/missions/survey_forest_sensed.yaml), without an
autopilot: the ground station's items read back by the mission tool as the mission's legs, the
flight's processes for mppid and for ArduCopter's AUTO, and the survey's figures from a truth."""
from __future__ import annotations

import os

import numpy as np
import pytest
import yaml

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink: MAVLink 1 would be the process's for the tests after
from pymavlink import mavutil  # noqa: E402

from mppi_mission import autopilot_plan  # noqa: E402
from sitl_helpers import fake_ardupilot  # noqa: E402
from sitl_harness import ap_gcs, paths, survey  # noqa: E402
from sitl_harness.flights.ardupilot import BENDYRULER, HOME, ArduPilotFlight  # noqa: E402
from sitl_harness.flights.base import FlightError, FlightSpec  # noqa: E402

M = mavutil.mavlink
SURVEY = paths.MISSIONS / "survey_forest_sensed.yaml"
HOME_LLA = [float(v) for v in HOME.split(",")[:3]]


def _as_downloaded(items):
    """MISSION_ITEM_INTs as the bridge's `mission download` gives them."""
    keys = ("seq", "frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z")
    return {"dialect": "ardupilot", "items": [{k: getattr(m, k) for k in keys} for m in items],
            "home": HOME_LLA, "origin": HOME_LLA, "fence": {}, "current": 1}


def test_the_uploaded_survey_reads_back_as_its_legs():
    doc = yaml.safe_load(SURVEY.read_text())
    items = ap_gcs.mission_items(doc, HOME_LLA)
    c = autopilot_plan.convert(_as_downloaded(items), here=[0.0, 0.0, 0.0], speed=2.0)
    assert c.mission.takeoff == pytest.approx(doc["takeoff"]) and c.mission.land
    lines = [leg["line"] for leg in c.mission.legs if "line" in leg]
    goals = [leg["goal"] for leg in c.mission.legs if "goal" in leg]
    want = [leg["goal"]["at"] for leg in doc["legs"]]
    assert len(goals) >= len(want)
    assert np.allclose([g["at"] for g in goals[:len(want)]], want, atol=0.05)       # where the legs said
    assert [g["radius"] for g in goals[:len(want)]] == [leg["goal"]["radius"] for leg in doc["legs"]]
    assert {ln["speed"] for ln in lines} == {doc["autopilot_mission"]["speed"]}      # DO_CHANGE_SPEED
    assert ap_gcs.last_waypoint(items) == len(want) + 2                             # home, takeoff, speed first
    assert items[-1].command == M.MAV_CMD_NAV_LAND


def _flight(tmp_path, controller):
    spec = FlightSpec(scenario="survey_forest_sensed", seed=51, out=tmp_path / controller, realtime=True,
                      autopilot="ardupilot", controller=controller, ardupilot_bin=str(fake_ardupilot(tmp_path / f"ap-{controller}")))
    flight = ArduPilotFlight.create(spec)
    flight.out.mkdir(parents=True)
    return flight.plan().commands


def test_mppid_reads_the_mission_the_ground_station_uploaded(mppid_binary, tmp_path):
    cmds = _flight(tmp_path, "mppid")
    assert {"gcs", "controller", "bridge", "sensors", "mapper"} <= set(cmds)
    assert "from-autopilot" in cmds["mission"] and "--fly-auto" not in cmds["gcs"]
    assert str(BENDYRULER) not in " ".join(cmds["sim"])                  # ArduCopter's avoidance off


def test_the_baseline_is_arducopters_auto_with_bendyruler_on_the_same_map(mppid_binary, tmp_path):
    cmds = _flight(tmp_path, "auto")
    assert "controller" not in cmds and "gcs" not in cmds
    assert "--fly-auto" in cmds["mission"]                                # the ground station starts AUTO
    assert str(BENDYRULER) in " ".join(cmds["sim"])
    assert {"bridge", "sensors", "mapper"} <= set(cmds)                   # the map, as OBSTACLE_DISTANCE
    with pytest.raises(FlightError, match="mppid or --controller auto"):
        _flight(tmp_path, "guided")


WORLD = {"waypoints": [[10, 0, 2], [10, 6, 2]], "acceptance": [1.0, 1.0], "forest_box": [[2, 8], [-2, 2]]}


def _truth(points, dt=0.1, n=50):
    X = np.concatenate([np.linspace(a, b, n) for a, b in zip(points[:-1], points[1:])])
    t = np.arange(len(X)) * dt
    return t, X, np.gradient(X, dt, axis=0)


def test_the_survey_is_scored_in_order_from_the_take_off():
    t, X, V = _truth([[0, 0, 0], [0, 0, 2], [10, 0, 2], [10, 6, 2]])
    f = survey.figures(WORLD, t, X, V)
    assert f["waypoints_reached"] == 2
    assert f["time_to_last_item_s"] == pytest.approx(t[f["last_item_index"]] - t[np.argmax(X[:, 2] > 0.5)])
    assert f["forest_mean_speed"] == pytest.approx(10 / (49 * 0.1), rel=0.03)    # the leg through the box
    # The second waypoint first, then the first: only the first counts (in order).
    t, X, V = _truth([[0, 0, 0], [0, 0, 2], [10, 6, 2], [10, 0, 2]])
    f = survey.figures(WORLD, t, X, V)
    assert f["waypoints_reached"] == 1 and f["time_to_last_item_s"] is None


def test_a_guided_segment_is_bracketed_for_mppid_and_auto_flies_the_rest(mppid_binary, tmp_path):
    doc = yaml.safe_load((paths.MISSIONS / "survey_guided_segment.yaml").read_text())
    cmds = [m.command for m in ap_gcs.mission_items(doc, HOME_LLA)]
    enable = cmds.index(M.MAV_CMD_NAV_GUIDED_ENABLE)
    assert cmds[enable - 1] == M.MAV_CMD_DO_GUIDED_LIMITS                 # a timeout, so AUTO goes on
    assert cmds[enable + 1:enable + 3] == [M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_GUIDED_ENABLE]
    assert cmds.count(M.MAV_CMD_NAV_WAYPOINT) == 1 + len(doc["legs"])     # home, then the legs
    spec = FlightSpec(scenario="survey_guided_segment", seed=51, out=tmp_path / "o", realtime=True,
                      autopilot="ardupilot", ardupilot_bin=str(fake_ardupilot(tmp_path)))
    flight = ArduPilotFlight.create(spec)
    flight.out.mkdir(parents=True)
    plan = flight.plan().commands
    assert "--fly-auto" in plan["mission"] and "from-autopilot" in plan["segments"]   # AUTO, mppid inside it
    assert str(BENDYRULER) not in " ".join(plan["sim"])


def test_loiter_pushed_at_a_trunk_runs_the_map_to_arducopter_with_mppid_not_flying(mppid_binary, tmp_path):
    spec = FlightSpec(scenario="loiter_toward_trunk", seed=51, out=tmp_path / "o", realtime=True,
                      autopilot="ardupilot", controller="loiter", ardupilot_bin=str(fake_ardupilot(tmp_path)))
    flight = ArduPilotFlight.create(spec)
    flight.out.mkdir(parents=True)
    cmds = flight.plan().commands
    assert "controller" not in cmds and {"bridge", "sensors", "mapper"} <= set(cmds)
    assert "--loiter-push" in cmds["mission"]
    assert "loiter_avoid.parm" in " ".join(cmds["sim"]) and str(BENDYRULER) not in " ".join(cmds["sim"])
    world = ap_gcs.write_world(yaml.safe_load((paths.MISSIONS / "loiter_toward_trunk.yaml").read_text()), 51,
                               flight.out)
    heading = np.degrees(np.arctan2(world[0][0], world[0][1])) % 360    # the trunk ahead of the home heading
    assert len(world) == 1 and heading == pytest.approx(float(HOME.split(",")[3]), abs=1.0)
