"""ArduPilot Copter: GUIDED with attitude/rate targets. GUIDED takes any SET_ATTITUDE_TARGET
over its own take-off, so nothing is streamed before `offboard` (no pre-stream) and `offboard`
waits for a take-off to end. The thrust is read as thrust only with GUID_OPTIONS bit 3. A lost
stream in GUIDED only levels the vehicle after GUID_TIMEOUT and holds its altitude, drifting:
so the bridge hands it to BRAKE itself (`hand_back`, failsafe.py), as it does for `hold`.

BRAKE, not LOITER: LOITER reads the pilot's throttle stick as a climb rate, and a vehicle flown
in GUIDED may have its stick anywhere, or no RC at all. ArduCopter SITL (no RC: the stick at
its minimum), handed to LOITER at 3 m/s in mid-circle, braked and then sank at 2.4 m/s into the
ground 1.7 s later (tools/ardupilot/package-flights.sh, docs/ardupilot.md). BRAKE stops the
vehicle and holds its position and altitude whatever the sticks do, until the pilot or the
ground station changes mode.

AUTO's guided sub-mode (a NAV_GUIDED_ENABLE item with param1 > 0 current in AUTO: ArduCopter's
mode_auto.cpp nav_guided_start) takes attitude targets as GUIDED does (in_guided_mode()), so
the bridge engages there without a mode change (`segment`); AUTO stays the operator's mode."""
from __future__ import annotations

from .base import CUSTOM, AutopilotProfile, mavlink

AUTO = 3
GUIDED = 4
BRAKE = 17
LAND = 9
RTL = 6
GUID_OPTIONS_THRUST_AS_THRUST = 8


class ArduPilot(AutopilotProfile):
    name = "ardupilot"
    mav_autopilot = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    hover_param = "MOT_THST_HOVER"
    prestream = False
    obstacle_distance_3d = True
    guided_segments = True    # NAV_GUIDED_ENABLE inside AUTO (the module doc)
    # ArduPilot sends no ODOMETRY: the bridge pairs the attitude with the latest position.
    state_messages = (mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)

    def flight_check(self, read_param) -> str:
        g = int(read_param("GUID_OPTIONS"))
        if g & GUID_OPTIONS_THRUST_AS_THRUST:
            return ""
        return (f"GUID_OPTIONS={g}: bit 3 (value 8, 'SetAttitudeTarget interprets Thrust As Thrust') "
                f"is not set, so ArduPilot would read the thrust as a climb rate; refusing to fly. "
                f"Set GUID_OPTIONS={g | 8} on the autopilot")

    def offboard_mode(self, custom_mode) -> bool:
        return custom_mode == GUIDED

    def before_offboard(self, engagement, wait_takeoff_s: float) -> None:
        engagement.wait_takeoff_done(wait_takeoff_s)

    def _guided(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, GUIDED], "mode GUIDED")

    def takeoff(self, ap, engagement, altitude: float) -> None:
        # ArduPilot flies any attitude target in GUIDED instead of its take-off.
        engagement.disengage("takeoff requested: the autopilot's own take-off flies")
        if ap.custom_mode != GUIDED:
            self._guided(ap)
        ap.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, [0, 0, 0, 0, 0, 0, altitude], "takeoff")
        engagement.takeoff_started()

    def offboard(self, ap) -> str:
        self._guided(ap)
        ap.wait_mode(lambda: ap.custom_mode == GUIDED, "mode GUIDED")
        return "GUIDED, attitude/rate targets"

    def in_mission_mode(self, custom_mode) -> bool:
        return custom_mode == AUTO

    def mission_mode(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, AUTO], "mode AUTO")
        ap.wait_mode(lambda: ap.custom_mode == AUTO, "mode AUTO")

    def rtl(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, RTL], "mode RTL")

    def land(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, LAND], "mode LAND")

    def hold(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, BRAKE], "mode BRAKE")

    def hand_back(self, ap) -> str:
        self.hold(ap)
        return "BRAKE"


PROFILE = ArduPilot()
