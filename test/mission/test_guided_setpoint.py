"""What the autopilots' own position controllers are sent when they fly a mission (the GUIDED
baseline on ArduCopter, PX4's offboard position control: mppi_mission.vehicles.GuidedLink,
which sitl_harness.px4_offboard extends): SET_POSITION_TARGET_LOCAL_NED in NED, the heading
the mission asks for turned from ENU (0: east, counter-clockwise) to NED (0: north, clockwise)."""
import math
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mppi_mission.vehicles import GuidedLink


class Recorder:
    def __init__(self):
        self.sent = []

    def set_position_target_local_ned_send(self, *args):
        self.sent.append(args)


def _link():
    link = GuidedLink.__new__(GuidedLink)   # no connection: the setpoint alone
    GuidedLink.__bases__[0].__init__(link)
    link.mavlink, link.target = mavlink, 7
    link.conn = SimpleNamespace(mav=Recorder())
    link._set_state(1_000_000, [0.0, 0.0, 0.0], 0.0)
    return link


@pytest.mark.parametrize("yaw_enu_deg,yaw_ned_deg", [(0, 90), (60, 30), (90, 0), (180, -90), (-90, 180)])
def test_the_mission_heading_goes_out_in_ned(yaw_enu_deg, yaw_ned_deg):
    link = _link()
    ref = {"kind": "hold", "center": [1.0, 2.0, 3.0], "yaw": math.radians(yaw_enu_deg)}
    link.send(ref, 1_000_000, [])
    (args,) = link.conn.mav.sent
    target, frame, (x, y, z), yaw = args[1], args[3], args[5:8], args[14]
    assert target == 7 and frame == mavlink.MAV_FRAME_LOCAL_NED
    assert (x, y, z) == pytest.approx((2.0, 1.0, -3.0))        # ENU (1, 2, 3) is 2 m north, 1 m east, 3 m up
    assert math.remainder(yaw - math.radians(yaw_ned_deg), math.tau) == pytest.approx(0.0, abs=1e-9)
