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


def _msg(t, **fields):
    m = SimpleNamespace(get_type=lambda: t, get_srcSystem=lambda: fields.get("src", 7),
                        get_srcComponent=lambda: fields.get("comp", 1), **fields)
    return m


def test_the_links_read_position_arming_and_acks_from_their_autopilot():
    """GuidedLink's message handler (ArduCopter GUIDED) and the PX4 offboard link's on top of
    it: position (NED -> ENU), arming from the autopilot's heartbeat (a ground station's is
    not the vehicle's), command acks; PX4's heading and parameters besides."""
    from sitl_harness.px4_offboard import Px4OffboardLink
    link = _link()
    link.armed, link.acks, link.custom_mode = False, {}, None
    link._on_message("LOCAL_POSITION_NED", _msg("LOCAL_POSITION_NED", time_boot_ms=2000, x=1.0, y=2.0, z=-3.0))
    assert list(link.position()) == pytest.approx([2.0, 1.0, 3.0])
    gcs = _msg("HEARTBEAT", type=mavlink.MAV_TYPE_GCS, base_mode=mavlink.MAV_MODE_FLAG_SAFETY_ARMED, custom_mode=4)
    link._on_message("HEARTBEAT", gcs)
    assert not link.armed
    ap = _msg("HEARTBEAT", type=mavlink.MAV_TYPE_QUADROTOR, base_mode=mavlink.MAV_MODE_FLAG_SAFETY_ARMED, custom_mode=4)
    link._on_message("HEARTBEAT", ap)
    assert link.armed and link.custom_mode == 4
    link._on_message("COMMAND_ACK", _msg("COMMAND_ACK", command=400, result=0))
    assert link.acks == {400: 0}

    px4 = Px4OffboardLink.__new__(Px4OffboardLink)
    px4.__dict__.update(link.__dict__, params={}, armed=False, yaw=None)
    px4._on_message("HEARTBEAT", _msg("HEARTBEAT", comp=191, type=mavlink.MAV_TYPE_QUADROTOR,
                                      base_mode=mavlink.MAV_MODE_FLAG_SAFETY_ARMED, custom_mode=6))
    assert not px4.armed                                    # the bridge's heartbeat, not PX4's
    px4._on_message("HEARTBEAT", ap)
    assert px4.armed
    c, s = math.cos(math.radians(15)), math.sin(math.radians(15))  # NED heading 30 deg: ENU 60 deg
    px4._on_message("ATTITUDE_QUATERNION", _msg("ATTITUDE_QUATERNION", q1=c, q2=0.0, q3=0.0, q4=s))
    assert px4.yaw == pytest.approx(math.radians(60))
    px4._on_message("PARAM_VALUE", _msg("PARAM_VALUE", param_id="COM_OF_LOSS_T", param_value=2.0))
    assert px4.params == {"COM_OF_LOSS_T": 2.0}
    px4._on_message("LOCAL_POSITION_NED", _msg("LOCAL_POSITION_NED", time_boot_ms=3000, x=0.0, y=0.0, z=-1.0))
    assert list(px4.position()) == pytest.approx([0.0, 0.0, 1.0])
