"""What the simulated autopilot (sim/mavlink_vehicle) learnt from the real PX4 (PX4 SITL with
SIH, docs/px4.md), checked on the stand-in itself, stepped in this process (no link traffic):

* PX4 flies the last rate setpoint on until COM_OF_LOSS_T runs out, then does COM_OBL_RC_ACT
  (a 3 rad/s roll rate flown through a 0.5 s pause turned the SIH vehicle over); ArduPilot's
  GUIDED stand-in levels 0.1 s after its last target, as before.
* PX4's offboard-loss failsafe is a mode fallback: OFFBOARD stays the intended mode, and
  setpoints arriving again take the vehicle back into it, unless a mode was commanded since
  (PX4 SITL: the link cut for 3 s, Hold, then OFFBOARD again on the bridge's pre-stream).
* PX4's data-link-loss failsafe: NAV_DLL_ACT after COM_DL_LOSS_T without a ground station's
  HEARTBEAT, once one was heard (the ground-link-loss row of docs/failsafes.md)."""
import math

import pytest
from mavlink_vehicle.vehicle import Vehicle

ROLL_RATE = 1.0   # rad/s, FRD p


def _airborne(autopilot, params=None):
    v = Vehicle("udpin:127.0.0.1:0", autopilot=autopilot, start=(0.0, 0.0, 20.0), params=params)
    v.armed = True
    v.set_mode("OFFBOARD" if autopilot == "px4" else "GUIDED")
    return v


def _fly(v, seconds):
    """Physics and supervision for `seconds` of simulated time, as Vehicle.run steps them."""
    for _ in range(int(round(seconds / v.dt))):
        v.plant.u = v.plant.saturate(v.control())
        v.plant.step(v.dt)
        v.t += v.dt
        v.supervise()


def _roll(v) -> float:
    w, x, y, z = v.plant.x[6:10]
    return math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))


def _last_setpoint(v, rates=(ROLL_RATE, 0.0, 0.0)):
    hover = v.params["MOT_THST_HOVER" if v.ap == "ardupilot" else "MPC_THR_HOVER"]
    v.setpoint, v.setpoint_t = (hover, *rates), v.t


def test_px4_flies_the_last_rate_setpoint_until_com_of_loss_t():
    v = _airborne("px4", {"COM_OF_LOSS_T": 0.5, "COM_OBL_RC_ACT": 5})
    _last_setpoint(v)                        # then nothing more: mppid paused, or died
    _fly(v, 0.45)
    assert v.mode == "OFFBOARD" and not [e for e in v.events if e["event"] == "failsafe"]
    assert v.plant.x[10] == pytest.approx(ROLL_RATE, abs=0.1), "still turning at the last setpoint's rate"
    assert _roll(v) > 0.3, f"rolled {_roll(v):.2f} rad in 0.45 s of the last setpoint"
    _fly(v, 0.1)
    fs = [e for e in v.events if e["event"] == "failsafe"]
    assert fs and fs[0]["reason"] == "offboard setpoints lost" and v.mode == "AUTO.LOITER"
    assert fs[0]["last_setpoint_age_s"] == pytest.approx(0.5, abs=0.01)


def test_px4_zero_rates_stop_the_turn():
    """What the bridge sends when its stream stops while engaged (forwarding.py): zero body
    rates (at the last thrust). PX4 flies that on instead: the turn stops where it was."""
    v = _airborne("px4", {"COM_OF_LOSS_T": 0.5})
    _last_setpoint(v)
    _fly(v, 0.1)
    rolled = _roll(v)
    _last_setpoint(v, (0.0, 0.0, 0.0))
    _fly(v, 0.35)
    assert abs(v.plant.x[10]) < 0.05
    assert _roll(v) == pytest.approx(rolled, abs=0.05)


def test_ardupilot_levels_after_its_last_target():
    v = _airborne("ardupilot", {"GUID_OPTIONS": 8})
    _last_setpoint(v)
    _fly(v, 0.45)
    assert abs(_roll(v)) < 0.2, "the GUIDED stand-in holds level 0.1 s after the last target"


@pytest.mark.parametrize("action,mode", [(1, "AUTO.LOITER"), (3, "AUTO.LAND")])
def test_px4_data_link_loss_does_what_nav_dll_act_says(action, mode):
    """mppid flying (OFFBOARD, its setpoints fresh), the ground station silent: after
    COM_DL_LOSS_T PX4 leaves OFFBOARD for NAV_DLL_ACT's mode, which disengages the bridge."""
    v = _airborne("px4", {"NAV_DLL_ACT": action, "COM_DL_LOSS_T": 1.0, "COM_OF_LOSS_T": 5.0})
    v.last_gcs_t = v.t                       # a ground station heard, then silent
    _last_setpoint(v, (0.0, 0.0, 0.0))
    _fly(v, 0.9)
    assert v.mode == "OFFBOARD" and not [e for e in v.events if e["event"] == "failsafe"]
    _fly(v, 0.2)
    fs = [e for e in v.events if e["event"] == "failsafe"]
    assert len(fs) == 1 and fs[0]["reason"] == "ground station lost" and v.mode == mode


def test_px4_data_link_loss_off_by_default():
    v = _airborne("px4", {"COM_OF_LOSS_T": 60.0})
    v.last_gcs_t = v.t
    _last_setpoint(v, (0.0, 0.0, 0.0))
    _fly(v, 11.0)
    assert v.mode == "OFFBOARD" and not [e for e in v.events if e["event"] == "failsafe"]


def test_px4_fallback_ends_on_a_setpoint_unless_a_mode_was_commanded():
    from pymavlink import mavutil
    ml = mavutil.mavlink
    mav = ml.MAVLink(None, srcSystem=1, srcComponent=191)
    sp = mav.set_attitude_target_encode(0, 1, 1, ml.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE, [1, 0, 0, 0],
                                        0.0, 0.0, 0.0, 0.4)
    sp.pack(mav)   # the header a received message has
    for commanded in (False, True):
        v = _airborne("px4", {"COM_OF_LOSS_T": 0.5, "COM_OBL_RC_ACT": 5})
        v.on_setpoint(sp, 0)
        _fly(v, 0.6)
        assert v.mode == "AUTO.LOITER"
        if commanded:   # a ground station (or RC) chose Hold: the intended mode moved
            v.set_mode("AUTO.LOITER", "command")
        v.on_setpoint(sp, 0)
        assert v.mode == ("AUTO.LOITER" if commanded else "OFFBOARD")
        assert bool([e for e in v.events if e["event"] == "offboard_resumed"]) is not commanded
