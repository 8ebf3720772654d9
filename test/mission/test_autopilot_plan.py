"""The autopilot's mission (its items as the bridge reads them) as the mission tool's plan:
global positions to the local frame, each item's legs, DO_JUMP unrolled, and every refusal
naming the item as the ground station numbers it. Offline: no link, no vehicle."""
import math

import numpy as np
import pytest
from pymavlink import mavextra, mavutil

from mppi_mission import autopilot_plan as ap

M = mavutil.mavlink
ORIGIN = (-35.3632621, 149.1652374, 584.0)
HOME = ORIGIN[:2] + (586.0,)          # home 2 m above the local frame's origin
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def item(seq, cmd, x=0.0, y=0.0, z=0.0, p=(0, 0, 0, 0), frame=REL):
    """An item as a ground station writes it: x, y metres east, north of home -> lat, lon."""
    lat, lon = (0, 0) if (x, y) == (0.0, 0.0) else mavextra.gps_offset(HOME[0], HOME[1], x, y)
    return {"seq": seq, "frame": frame, "command": cmd, "autocontinue": 1, "param1": p[0], "param2": p[1],
            "param3": p[2], "param4": p[3], "x": int(round(lat * 1e7)), "y": int(round(lon * 1e7)), "z": z}


def download(items, dialect="ardupilot", fence=None):
    if dialect == "ardupilot":
        items = [item(0, M.MAV_CMD_NAV_WAYPOINT, frame=M.MAV_FRAME_GLOBAL_INT, z=HOME[2])] + items
    return {"dialect": dialect, "items": items, "home": HOME, "origin": ORIGIN, "fence": fence or {}, "current": 1}


def survey(first=1):
    s = first
    return [item(s, M.MAV_CMD_NAV_TAKEOFF, z=3.0),
            item(s + 1, M.MAV_CMD_NAV_WAYPOINT, 10.0, 0.0, 3.0, p=(2.0, 1.5, 0, 0)),
            item(s + 2, M.MAV_CMD_DO_CHANGE_SPEED, p=(1, 4.0, -1, 0), frame=M.MAV_FRAME_MISSION),
            item(s + 3, M.MAV_CMD_NAV_WAYPOINT, 10.0, 10.0, 591.0, frame=M.MAV_FRAME_GLOBAL_INT),
            item(s + 4, M.MAV_CMD_CONDITION_YAW, p=(180.0, 90.0, 0, 0), frame=M.MAV_FRAME_MISSION),
            item(s + 5, M.MAV_CMD_NAV_LOITER_TIME, p=(5.0, 0, 0, 0), z=4.0),
            item(s + 6, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=M.MAV_FRAME_MISSION)]


def test_a_survey_becomes_legs_in_the_local_frame():
    c = ap.convert(download(survey()), here=[0.0, 0.0, 0.0], speed=2.0)
    legs, m = c.mission.legs, c.mission
    assert m.takeoff == pytest.approx(3.0) and not m.land and m.frame == "local"
    assert [next(iter(leg)) for leg in legs] == ["line", "goal", "hold", "line", "goal", "hold", "line", "hold"]
    assert c.leg_items == [2, 2, 2, 4, 4, 5, 6, 6]
    assert c.handback_item == 7                      # the return is the autopilot's own
    # Home 2 m above the origin: relative 3 m is local z 5; AMSL 591 m is local z 7.
    assert np.allclose(legs[0]["line"]["to"], [10.0, 0.0, 5.0], atol=0.01)
    assert legs[0]["line"]["speed"] == 2.0 and legs[3]["line"]["speed"] == 4.0   # DO_CHANGE_SPEED
    assert legs[1]["goal"]["radius"] == 1.5 and legs[2]["hold"]["for"] == 2.0    # acceptance radius, hold time
    assert np.allclose(legs[3]["line"]["to"], [10.0, 10.0, 7.0], atol=0.01)
    assert legs[5]["hold"]["yaw"] == pytest.approx(-90.0)                        # NED 180 (south): ENU -90
    assert np.allclose(legs[6]["line"]["to"], [10.0, 10.0, 6.0], atol=0.01)     # loiter at lat, lon 0: here
    assert legs[7]["hold"] == {"for": 5.0, "yaw": -90.0}
    assert c.numbers[2] == 2 and c.names[7] == "NAV_RETURN_TO_LAUNCH" and c.takeoff_item == 1


def test_px4_numbers_items_from_its_first_and_flies_from_the_air():
    c = ap.convert(download(survey(first=0), dialect="px4"), here=[1.0, 2.0, 4.0], airborne=True)
    assert c.mission.takeoff is None and c.takeoff_item == 0 and c.numbers[0] == 1
    assert c.leg_items[0] == 1 and c.numbers[1] == 2


def test_do_jump_is_unrolled_its_repeat_count_times():
    items = [item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0),
             item(3, M.MAV_CMD_NAV_WAYPOINT, 5.0, 5.0, 2.0),
             item(4, M.MAV_CMD_DO_JUMP, p=(2, 2, 0, 0), frame=M.MAV_FRAME_MISSION),
             item(5, M.MAV_CMD_NAV_LAND)]
    c = ap.convert(download(items), here=[0.0, 0.0, 0.0])
    assert [s for s in c.leg_items if s in (2, 3)] == [2, 2, 3, 3] * 3
    assert c.leg_items[-1] == 5 and c.mission.land


def test_flying_from_the_autopilots_current_item():
    c = ap.convert(download(survey()), here=[10.0, 0.0, 5.0], airborne=True, start_seq=4)
    assert c.leg_items[0] == 4 and c.mission.takeoff is None


@pytest.mark.parametrize("items, number, words", [
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_SPLINE_WAYPOINT, 5.0, 0.0, 2.0)], 2,
     "NAV_SPLINE_WAYPOINT: mppid cannot fly it"),
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0),
      item(3, M.MAV_CMD_DO_JUMP, p=(2, -1, 0, 0), frame=M.MAV_FRAME_MISSION)], 3, "repeat -1 loops for ever"),
    # PX4 keeps the repeat count in 16 bits: a ground station's -1 comes back 65535 (PX4 SITL, bench/results/
    # issue38_refusals): refused at the DO_JUMP, not at the waypoint it repeats.
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0),
      item(3, M.MAV_CMD_DO_JUMP, p=(2, 65535, 0, 0), frame=M.MAV_FRAME_MISSION)], 3,
     "DO_JUMP unrolls the mission past 1000 items"),
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_DO_JUMP, p=(9, 1, 0, 0))], 2, "no such item"),
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0),
      item(2, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0, frame=M.MAV_FRAME_LOCAL_NED)], 2, "frame MAV_FRAME_LOCAL_NED"),
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_LAND), item(3, M.MAV_CMD_NAV_WAYPOINT, 1, 1, 2)],
     3, "NAV_WAYPOINT after the landing (item 2)"),
    ([item(1, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0)], 1, "on the ground and the mission has no NAV_TAKEOFF"),
    ([item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0),
      item(3, M.MAV_CMD_NAV_WAYPOINT, 40.0, 0.0, 2.0)], 3, "NAV_WAYPOINT leaves the geofence"),
    ([], None, "empty"),
])
def test_a_mission_mppid_cannot_fly_is_refused_naming_the_item(items, number, words):
    fence = {"shape": "cylinder", "center": [0.0, 0.0], "radius": 30.0}
    with pytest.raises(ap.Refusal) as e:
        ap.convert(download(items, fence=fence), here=[0.0, 0.0, 0.0])
    assert e.value.number == number and words in str(e.value), str(e.value)
    if number is not None:
        assert str(e.value).startswith(f"mission item {number}: ")


def test_a_relative_yaw_turns_from_the_vehicles_heading():
    items = [item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0),
             item(2, M.MAV_CMD_CONDITION_YAW, p=(30.0, 0, -1, 1), frame=M.MAV_FRAME_MISSION)]
    c = ap.convert(download(items), here=[0.0, 0.0, 0.0], heading_deg=10.0)
    assert math.isclose(c.mission.legs[0]["hold"]["yaw"], 40.0)   # 30 deg counter-clockwise from 10


def test_a_landing_at_a_point_flies_above_it_first():
    items = [item(1, M.MAV_CMD_NAV_TAKEOFF, z=2.0), item(2, M.MAV_CMD_NAV_LAND, 3.0, 4.0, 0.0)]
    c = ap.convert(download(items), here=[0.0, 0.0, 0.0])
    assert np.allclose(c.mission.legs[0]["line"]["to"], [3.0, 4.0, 4.0], atol=0.01)   # at the take-off altitude
    assert c.leg_items == [2] and c.mission.land


def test_unset_params_take_their_defaults_and_a_value_out_of_range_names_its_item():
    nan = float("nan")
    items = [item(0, M.MAV_CMD_NAV_TAKEOFF, z=2.0, p=(nan, nan, nan, nan)),   # PX4 as QGroundControl writes it
             item(1, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 2.0, p=(nan, nan, nan, nan)),
             item(2, M.MAV_CMD_NAV_LOITER_TIME, z=2.0, p=(nan, nan, nan, nan))]
    c = ap.convert(download(items, dialect="px4"), here=[0.0, 0.0, 0.0])
    assert c.mission.legs[1]["goal"]["radius"] == ap.DEFAULT_RADIUS and c.mission.legs[2] == {"hold": {"for": 0.0}}
    items[2] = item(2, M.MAV_CMD_NAV_LOITER_TIME, z=2.0, p=(1e7, 0, 0, 0))
    with pytest.raises(ap.Refusal) as e:
        ap.convert(download(items, dialect="px4"), here=[0.0, 0.0, 0.0])
    assert e.value.number == 3 and "hold.for" in str(e.value)


# ---- ArduCopter's guided segments (guided_segments.py) ---------------------------------------
def _segmented():
    ge, mis = M.MAV_CMD_NAV_GUIDED_ENABLE, M.MAV_FRAME_MISSION
    return download([item(1, M.MAV_CMD_NAV_TAKEOFF, z=3.0), item(2, M.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 3.0),
                     item(3, ge, p=(1, 0, 0, 0), frame=mis), item(4, M.MAV_CMD_NAV_WAYPOINT, 5.0, 5.0, 3.0),
                     item(5, M.MAV_CMD_NAV_WAYPOINT, 0.0, 5.0, 3.0), item(6, ge, p=(0, 0, 0, 0), frame=mis),
                     item(7, M.MAV_CMD_NAV_WAYPOINT, 0.0, 8.0, 3.0), item(8, ge, p=(1, 0, 0, 0), frame=mis),
                     item(9, M.MAV_CMD_NAV_WAYPOINT, 3.0, 8.0, 3.0)])


def test_guided_segments_are_the_items_between_the_enables():
    from mppi_mission import guided_segments as gs
    dl = _segmented()
    segs = gs.check(dl)
    assert [(g.enable, g.end) for g in segs] == [(3, 6), (8, 10)]      # the last one runs to the mission's end
    c = gs.convert(dl, segs[0], here=[5.0, 0.0, 5.0])
    assert sorted(set(c.leg_items)) == [4, 5] and not c.mission.land and c.mission.takeoff is None
    assert np.allclose(c.mission.legs[-2]["line"]["to"], [0.0, 5.0, 5.0], atol=0.01)


def test_a_guided_segment_mppid_cannot_fly_is_refused_naming_the_item():
    from mppi_mission import guided_segments as gs
    dl = _segmented()
    dl["items"][9] = item(9, M.MAV_CMD_NAV_LAND)
    with pytest.raises(ap.Refusal, match="mission item 9: NAV_LAND inside a guided segment"):
        gs.check(dl)
    dl["items"][9] = item(9, M.MAV_CMD_NAV_SPLINE_WAYPOINT, 3.0, 8.0, 3.0)
    with pytest.raises(ap.Refusal, match="mission item 9: NAV_SPLINE_WAYPOINT: mppid cannot fly it"):
        gs.check(dl)
    with pytest.raises(ap.Refusal, match="PX4 has no such item"):
        gs.check({**_segmented(), "dialect": "px4"})
