"""What the bridge needs to know of one autopilot, in one place: an `AutopilotProfile`.

A profile answers the questions the bridge used to answer with `if dialect == ...`: whether
mppid's setpoints are streamed before `offboard` (the pre-stream), which parameter holds the
hover thrust and how its PARAM_VALUE is decoded, which telemetry states are built from, and
the take-off / offboard / land / hold sequences. It holds no state of its own: the sequences
act through the `Autopilot` (autopilot.py: commands, parameters, the mode the HEARTBEAT
reports) and the `Engagement` (engagement.py) they are given. Adding an autopilot is adding
a file beside px4.py and ardupilot.py that defines `PROFILE`.
"""
from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

mavlink = mavutil.mavlink
CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


class AutopilotProfile:
    name = ""                 # the settings' mavlink.dialect
    mav_autopilot = 0         # MAV_AUTOPILOT_* in its HEARTBEAT
    hover_param = ""          # the hover thrust fraction (0..1) parameter
    prestream = False         # mppid's setpoints go to the wire before the first `offboard`
    state_messages = ()       # message ids the states are built from (telemetry.py asks for them)
    # The autopilot flies the last rate setpoint on when the stream stops, until its own
    # offboard-loss timeout (PX4: COM_OF_LOSS_T): a paused stream then ends with one setpoint
    # of zero body rates at the last thrust (forwarding.py).
    flies_last_setpoint = False
    guided_segments = False   # the autopilot hands parts of its own mission to mppid (ArduPilot NAV_GUIDED_ENABLE)
    # The autopilot's offboard-loss failsafe is a fallback that ends by itself when setpoints
    # arrive again (PX4: OFFBOARD stays the intended mode): after the bridge's own failsafe
    # disengaged it, nothing may be pre-streamed until `offboard` (engagement.py).
    offboard_loss_resumes = False
    # The autopilot takes OBSTACLE_DISTANCE_3D (ArduPilot's AP_Proximity_MAV) beside
    # OBSTACLE_DISTANCE (obstacle_distance.py).
    obstacle_distance_3d = False

    def decode_param(self, msg) -> float:
        """PARAM_VALUE's value as a number."""
        return float(msg.param_value)

    def flight_check(self, read_param) -> str:
        """Parameters that make flying through this bridge wrong: why, or ''."""
        return ""

    def offboard_mode(self, custom_mode) -> bool:
        """Whether the HEARTBEAT's custom mode is the one mppid's setpoints fly in."""
        raise NotImplementedError

    def before_offboard(self, engagement, wait_takeoff_s: float) -> None:
        """What `offboard` does before it looks at mppid's stream."""

    def takeoff(self, ap, engagement, altitude: float) -> None:
        raise NotImplementedError

    def offboard(self, ap) -> str:
        """Switches into the offboard mode and waits for the HEARTBEAT to confirm; the answer's text."""
        raise NotImplementedError

    def land(self, ap) -> None:
        raise NotImplementedError

    def hold(self, ap) -> None:
        raise NotImplementedError

    def in_mission_mode(self, custom_mode) -> bool:
        """Whether the autopilot flies its stored mission itself (ArduPilot AUTO, PX4 AUTO.MISSION)."""
        raise NotImplementedError

    def mission_mode(self, ap) -> None:
        """Switches to the mode that flies the stored mission from its current item."""
        raise NotImplementedError

    def rtl(self, ap) -> None:
        """The autopilot's own return to launch."""
        raise NotImplementedError

    def hand_back(self, ap) -> str:
        """After mppid's stream stopped while engaged: what the bridge asks of the autopilot
        (a mode name), or '' to leave it to the autopilot's own offboard-loss failsafe."""
        return ""
