"""The autopilot profiles (mppi_mavlink/autopilots/): what each answers and the commands each
sequence sends, against a recording autopilot; adding a profile is adding a file."""
import math
import struct

import pytest

from mppi_mavlink import autopilots, settings
from mppi_mavlink.autopilots.base import mavlink
from mppi_mavlink.engagement import Engagement

SET_MODE, TAKEOFF, LAND = mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND


class Recorder:
    """The Autopilot's request side, recorded; the mode follows each DO_SET_MODE."""

    def __init__(self, custom_mode=0, params=None, px4=False):
        self.custom_mode, self.sent, self.params, self.px4 = custom_mode, [], params or {}, px4

    def command_long(self, command, params, name):
        self.sent.append((command, [p for p in params]))
        if command == SET_MODE:
            self.custom_mode = (int(params[1]) << 16 | int(params[2]) << 24) if self.px4 else int(params[1])

    def param_set(self, name, value):
        self.sent.append(("PARAM_SET", name, value))

    def wait_mode(self, predicate, what):
        assert predicate(), what

    def read_param(self, name):
        return self.params[name]


def test_every_profile_file_is_a_dialect():
    assert autopilots.available() == ["ardupilot", "px4"]
    for name in autopilots.available():
        assert autopilots.load(name).name == name
    with pytest.raises(ValueError):
        autopilots.load("inav")
    with pytest.raises(settings.SettingsError, match="ardupilot, px4"):
        settings.load(None, ["mavlink.dialect=inav"])


@pytest.mark.parametrize("name,prestream,hover,autopilot", [
    ("px4", True, "MPC_THR_HOVER", mavlink.MAV_AUTOPILOT_PX4),
    ("ardupilot", False, "MOT_THST_HOVER", mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)])
def test_profile_answers(name, prestream, hover, autopilot):
    p = autopilots.load(name)
    assert (p.prestream, p.hover_param, p.mav_autopilot) == (prestream, hover, autopilot)
    assert mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION in p.state_messages
    assert (mavlink.MAVLINK_MSG_ID_ODOMETRY in p.state_messages) == (name == "px4")


def test_offboard_modes():
    px4, apm = autopilots.load("px4"), autopilots.load("ardupilot")
    assert px4.offboard_mode(6 << 16) and not px4.offboard_mode(4 << 16 | 3 << 24) and not px4.offboard_mode(None)
    assert apm.offboard_mode(4) and not apm.offboard_mode(5)


class Msg:
    def __init__(self, value, ptype):
        self.param_value, self.param_type = value, ptype


def test_parameter_decoding():
    as_float = struct.unpack("<f", struct.pack("<i", 8))[0]  # PX4 sends an integer byte-wise
    assert autopilots.load("px4").decode_param(Msg(as_float, mavlink.MAV_PARAM_TYPE_INT32)) == 8.0
    assert autopilots.load("px4").decode_param(Msg(0.4, mavlink.MAV_PARAM_TYPE_REAL32)) == pytest.approx(0.4)
    assert autopilots.load("ardupilot").decode_param(Msg(8.0, mavlink.MAV_PARAM_TYPE_INT32)) == 8.0
    assert autopilots.decode_param(Msg(as_float, mavlink.MAV_PARAM_TYPE_INT32), mavlink.MAV_AUTOPILOT_PX4) == 8.0
    assert autopilots.decode_param(Msg(3.0, mavlink.MAV_PARAM_TYPE_INT32), mavlink.MAV_AUTOPILOT_GENERIC) == 3.0


def test_ardupilot_flight_check():
    apm = autopilots.load("ardupilot")
    assert apm.flight_check(Recorder(params={"GUID_OPTIONS": 8}).read_param) == ""
    why = apm.flight_check(Recorder(params={"GUID_OPTIONS": 1}).read_param)
    assert "GUID_OPTIONS=1" in why and "bit 3" in why and "GUID_OPTIONS=9" in why
    assert autopilots.load("px4").flight_check(Recorder().read_param) == ""


def test_px4_sequences():
    p, ap, e = autopilots.load("px4"), Recorder(custom_mode=4 << 16 | 3 << 24, px4=True), Engagement(True)
    p.takeoff(ap, e, 3.0)
    assert ap.sent[0] == ("PARAM_SET", "MIS_TAKEOFF_ALT", 3.0)
    assert ap.sent[1][0] == TAKEOFF and math.isnan(ap.sent[1][1][6])
    assert p.offboard(ap) == "OFFBOARD" and ap.sent[-1] == (SET_MODE, [1, 6, 0])
    p.land(ap)
    assert ap.sent[-1][0] == LAND
    p.hold(ap)
    assert ap.sent[-1] == (SET_MODE, [1, 4, 3])
    assert e.snapshot().state == "prestream"   # PX4's take-off leaves the pre-stream alone


def test_ardupilot_sequences():
    p, ap, e = autopilots.load("ardupilot"), Recorder(custom_mode=0), Engagement(False)
    e.engage(4, "GUIDED")
    p.takeoff(ap, e, 1.5)
    assert [c for c, _ in ap.sent] == [SET_MODE, TAKEOFF] and ap.sent[1][1][6] == 1.5
    s = e.snapshot()
    assert s.state == "disengaged" and s.takeoff_in_progress and "take-off" in s.why
    ap.sent.clear()
    p.takeoff(ap, e, 1.5)  # already in GUIDED: no mode change
    assert [c for c, _ in ap.sent] == [TAKEOFF]
    assert p.offboard(ap).startswith("GUIDED") and ap.sent[-1] == (SET_MODE, [1, 4])
    p.land(ap)
    assert ap.sent[-1] == (SET_MODE, [1, 9])
    p.hold(ap)
    assert ap.sent[-1] == (SET_MODE, [1, 17])  # BRAKE: holds whatever the sticks say (LOITER reads the throttle)
