"""The stored mission flown by the simulated autopilot itself: ArduCopter's AUTO and PX4's
AUTO.MISSION, with a simple position controller (the vehicle's own, at WPNAV_SPEED).

Items, as both autopilots run them: NAV_TAKEOFF (climb where it is), NAV_WAYPOINT (to within
its acceptance radius, param2, else 1 m; then its hold time, param1), NAV_LOITER_TIME,
NAV_LAND (above it, then down; disarmed on the ground), NAV_RETURN_TO_LAUNCH (above home at
the altitude flown, then down), DO_CHANGE_SPEED, DO_JUMP; other DO_ and CONDITION_ items pass.
Each NAV item done: MISSION_ITEM_REACHED (the autopilot's own), the next item current
(MISSION_CURRENT). The mission's end: it holds where it is (ArduCopter loiters, PX4 holds).

ArduCopter's hand-off to a companion computer (mode_auto.cpp, ArduCopter 4.5/4.6):
MAV_CMD_NAV_GUIDED_ENABLE with param1 > 0 starts AUTO's guided sub-mode (nav_guided_start:
GUIDED's init, holding where it is, and the limits' start time and position); attitude
targets are flown there as in GUIDED. The item is done only when a guided limit is passed
(verify_nav_guided_enable -> mode_guided.limit_check(): the timeout, the altitude below
alt_min or above alt_max, or farther than horiz_max from where it started, all set by
MAV_CMD_DO_GUIDED_LIMITS, 0 meaning none), or when the companion sets the current item
(MISSION_SET_CURRENT), which starts that item. With param1 = 0 the item is done at once.
Targets older than GUID_TIMEOUT s in the sub-mode: the vehicle levels and holds its climb
rate at 0 (mode_guided.cpp angle_control_run), and drifts.
"""
from __future__ import annotations

import math

from pymavlink import mavutil

from mppi_mavlink.layout import QuadrotorRate as Q

from .missions import EARTH_RADIUS, HOME

mavlink = mavutil.mavlink
NAV_GUIDED_ENABLE = 92
DO_GUIDED_LIMITS = 222
RELATIVE = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
NAV = {mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME,
       mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, NAV_GUIDED_ENABLE}


class Auto:
    def __init__(self, vehicle):
        self.v = vehicle
        self.seq = None            # the NAV item being flown (None: the mission's end, holding)
        self.target = None         # ENU position the vehicle's own controller flies to
        self.phase = ""            # "fly", "hold", "land", "guided"
        self.hold_until = None
        self.speed = None          # DO_CHANGE_SPEED's, else WPNAV_SPEED
        self.jumps = {}            # DO_JUMP seq -> jumps left
        self.limits = (0.0, 0.0, 0.0, 0.0)   # timeout s, alt min, alt max (m), horiz max (m)
        self.guided_start = None   # (t, position) where the guided sub-mode started
        self.guided_quiet = False  # GUID_TIMEOUT passed in the sub-mode

    @property
    def guided(self) -> bool:
        return self.phase == "guided"

    # ---- items ----------------------------------------------------------------------------
    def start(self, seq: int):
        """Runs the mission from item `seq`: DO items at once, up to the next NAV item."""
        store, v = self.v.missions, self.v
        self.phase, self.guided_start, self.guided_quiet = "", None, False
        while seq < len(store.items):
            it = store.items[seq]
            if it.command in NAV:
                store.current = seq
                self._nav(it)
                store.send_current()
                return
            seq = self._do(it, seq)
        self.seq, self.phase = None, "hold"
        self.target = list(v.plant.x[Q.POS])
        v.event("mission_complete")

    def _do(self, it, seq) -> int:
        """A DO/CONDITION item done; the next item's seq."""
        if it.command == mavlink.MAV_CMD_DO_CHANGE_SPEED and it.param2 > 0:
            self.speed = float(it.param2)
        elif it.command == DO_GUIDED_LIMITS:
            self.limits = (float(it.param1), float(it.param2), float(it.param3), float(it.param4))
        elif it.command == mavlink.MAV_CMD_DO_JUMP:
            left = self.jumps.setdefault(seq, int(it.param2))
            if left != 0:
                self.jumps[seq] = left - 1
                return int(it.param1)
        return seq + 1

    def _nav(self, it):
        v, x = self.v, self.v.plant.x
        self.seq, self.hold_until = it.seq, None
        here = list(x[Q.POS])
        if it.command == NAV_GUIDED_ENABLE:
            if it.param1 > 0.5:
                self.phase, self.guided_start = "guided", (v.t, here)
                self.target = here
                v.setpoint_t = None        # GUIDED's init: holds where it is until a target comes
                v.event("guided_segment", seq=it.seq, limits=list(self.limits))
            else:
                self.phase = "done"
            return
        if it.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            home = v.missions.home_enu
            self.target, self.phase = [home[0], home[1], here[2]], "fly"
            return
        p = self._point(it, here)
        if it.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            p[0], p[1] = here[0], here[1]
        self.target, self.phase = p, "fly"

    def _point(self, it, here):
        home = self.v.missions.home_enu
        z = home[2] + it.z if it.frame in RELATIVE else it.z - HOME[2]   # AMSL: against the origin's
        if it.x == 0 and it.y == 0:
            return [here[0], here[1], z]
        north = math.radians(it.x * 1e-7 - HOME[0]) * EARTH_RADIUS
        east = math.radians(it.y * 1e-7 - HOME[1]) * EARTH_RADIUS * math.cos(math.radians(HOME[0]))
        return [east, north, z]

    # ---- at the physics rate --------------------------------------------------------------
    def verify(self):
        """Whether the NAV item is done (then the next one starts)."""
        if self.seq is None:
            return
        v, x = self.v, self.v.plant.x
        it = v.missions.items[self.seq]
        if self.phase == "guided":
            why = self._limit_passed()
            if why:
                v.event("guided_limit", seq=self.seq, why=why)
                return self._next()
            return None
        if self.phase == "done":
            return self._next()
        if self.phase == "land" and v.plant.on_ground:   # the mission's end: reached, then disarmed
            self._reached(self.seq)
            self.phase = "landed"
        if self.phase in ("land", "landed"):
            return None
        d = math.dist(self.target, x[Q.POS])
        if it.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self._next() if x[Q.PZ] > self.target[2] - 0.2 else None
        if self.phase == "fly" and d < (it.param2 if it.command == mavlink.MAV_CMD_NAV_WAYPOINT and it.param2 > 0
                                        else 1.0):
            if it.command in (mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH):
                self.phase = "land"
                return None
            self.phase, self.hold_until = "hold", v.t + max(float(it.param1), 0.0)
        if self.phase == "hold" and v.t >= self.hold_until:
            self._next()
        return None

    def _limit_passed(self) -> str:
        """ModeGuided::limit_check: the segment's limits (0: none)."""
        timeout, alt_min, alt_max, horiz_max = self.limits
        t0, p0 = self.guided_start
        x = self.v.plant.x
        if timeout > 0 and self.v.t - t0 >= timeout:
            return f"timeout {timeout:g} s"
        if alt_min != 0 and x[Q.PZ] < alt_min:
            return f"below {alt_min:g} m"
        if alt_max != 0 and x[Q.PZ] > alt_max:
            return f"above {alt_max:g} m"
        if horiz_max > 0 and math.hypot(x[Q.PX] - p0[0], x[Q.PY] - p0[1]) > horiz_max:
            return f"farther than {horiz_max:g} m"
        return ""

    def _reached(self, seq):
        self.v.conn.mav.mission_item_reached_send(seq)
        self.v.event("mission_item_reached", seq=seq, src=1)

    def _next(self):
        self._reached(self.seq)
        self.start(self.seq + 1)

    def landed(self) -> bool:
        """On the ground after NAV_LAND or NAV_RETURN_TO_LAUNCH (the caller disarms)."""
        return self.phase in ("land", "landed") and self.v.plant.on_ground

    def control(self):
        """The vehicle's own command (None: the guided sub-mode's, the caller's)."""
        v, x = self.v, self.v.plant.x
        if self.phase == "guided":
            return None
        vmax = self.speed or (v.params["WPNAV_SPEED"] / 100.0 if v.ap == "ardupilot" else v.params["MPC_XY_CRUISE"])
        if self.phase in ("land", "landed"):
            return v.position_control([self.target[0], self.target[1], 0.0], vz_sp=-0.8 if x[Q.PZ] > 0.6 else -0.4)
        return v.position_control(self.target, vmax=vmax)

    def guided_timeout(self):
        """GUID_TIMEOUT passed without a target: levelled, climb rate 0."""
        if not self.guided_quiet:
            self.guided_quiet = True
            self.v.event("guided_timeout", seq=self.seq, z=round(float(self.v.plant.x[Q.PZ]), 3),
                         since_target_s=round(self.v.t - self.v.setpoint_t, 4))
        return self.v.position_control(list(self.v.plant.x[Q.POS]), vz_sp=0.0, level=True)
