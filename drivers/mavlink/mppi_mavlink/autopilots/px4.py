"""PX4: OFFBOARD mode, which needs a setpoint stream (> 2 Hz) before it is entered and ignores
setpoints outside it, so mppid's setpoints are pre-streamed (`prestream`). Integer parameters
arrive byte-wise in PARAM_VALUE's float. Losing the stream in OFFBOARD is PX4's own failsafe:
after COM_OF_LOSS_T it does what COM_OBL_RC_ACT says (docs/failsafes.md)."""
from __future__ import annotations

import math
import struct

from .base import CUSTOM, AutopilotProfile, mavlink

MAIN_OFFBOARD = 6
MAIN_AUTO = 4
SUB_LOITER = 3
SUB_MISSION = 4
SUB_RTL = 5
INTEGER_TYPES = (mavlink.MAV_PARAM_TYPE_INT32, mavlink.MAV_PARAM_TYPE_UINT32, mavlink.MAV_PARAM_TYPE_INT16,
                 mavlink.MAV_PARAM_TYPE_UINT16, mavlink.MAV_PARAM_TYPE_INT8, mavlink.MAV_PARAM_TYPE_UINT8)


def main_mode(custom_mode):
    """PX4's main mode: bits 16..23 of the custom mode."""
    return None if custom_mode is None else (custom_mode >> 16) & 0xFF


class Px4(AutopilotProfile):
    name = "px4"
    mav_autopilot = mavlink.MAV_AUTOPILOT_PX4
    hover_param = "MPC_THR_HOVER"
    prestream = True
    # PX4's rate controller flies the last vehicle_rates_setpoint until COM_OF_LOSS_T runs out:
    # met in SITL (docs/px4.md), 3 rad/s of roll for 0.5 s turned the vehicle over.
    flies_last_setpoint = True
    # PX4's offboard loss is a mode fallback (commander/failsafe: checkModeFallback), not a
    # latched failsafe: OFFBOARD stays the user's intended mode, and setpoints arriving again
    # take the vehicle back into it. Met in SITL: the link cut for 3 s, PX4 went to Hold, and
    # the bridge's pre-stream on the link's return took it back into OFFBOARD (docs/px4.md).
    offboard_loss_resumes = True
    state_messages = (mavlink.MAVLINK_MSG_ID_ODOMETRY, mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
                      mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)

    def decode_param(self, msg) -> float:
        if msg.param_type in INTEGER_TYPES:
            return float(struct.unpack("<i", struct.pack("<f", msg.param_value))[0])
        return float(msg.param_value)

    def offboard_mode(self, custom_mode) -> bool:
        return main_mode(custom_mode) == MAIN_OFFBOARD

    def before_offboard(self, engagement, wait_takeoff_s: float) -> None:
        engagement.prestream("offboard requested")  # pre-stream again after a stop

    def takeoff(self, ap, engagement, altitude: float) -> None:
        # PX4 reads param7 as AMSL; NaN takes MIS_TAKEOFF_ALT (above home), set first.
        ap.param_set("MIS_TAKEOFF_ALT", altitude)
        ap.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, [-1.0, 0, 0, math.nan, math.nan, math.nan, math.nan], "takeoff")

    def offboard(self, ap) -> str:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, MAIN_OFFBOARD, 0], "mode OFFBOARD")
        ap.wait_mode(lambda: self.offboard_mode(ap.custom_mode), "mode OFFBOARD")
        return "OFFBOARD"

    def in_mission_mode(self, custom_mode) -> bool:
        return custom_mode is not None and main_mode(custom_mode) == MAIN_AUTO and (custom_mode >> 24) == SUB_MISSION

    def mission_mode(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, MAIN_AUTO, SUB_MISSION], "mode AUTO.MISSION")
        ap.wait_mode(lambda: self.in_mission_mode(ap.custom_mode), "mode AUTO.MISSION")

    def rtl(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, MAIN_AUTO, SUB_RTL], "mode AUTO.RTL")

    def land(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_NAV_LAND, [0, 0, 0, math.nan, math.nan, math.nan, math.nan], "land")

    def hold(self, ap) -> None:
        ap.command_long(mavlink.MAV_CMD_DO_SET_MODE, [CUSTOM, MAIN_AUTO, SUB_LOITER], "mode HOLD")


PROFILE = Px4()
