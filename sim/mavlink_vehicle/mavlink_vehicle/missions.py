"""The simulated autopilot's mission store and its side of the MAVLink mission protocol, as
PX4 and ArduPilot have them: a ground station uploads (MISSION_COUNT -> MISSION_REQUEST_INT
-> MISSION_ITEM_INT ... -> MISSION_ACK), anyone downloads (MISSION_REQUEST_LIST ->
MISSION_COUNT -> MISSION_REQUEST_INT -> MISSION_ITEM_INT ... -> MISSION_ACK), MISSION_CURRENT
once a second and at once after a change (a new upload: the new total, the current item back
to the first; MISSION_SET_CURRENT), MISSION_CLEAR_ALL. ArduPilot's item 0 is home (the ground
station uploads it first, and a download gets it back); PX4's list starts at the first item.

Also what a ground station sees of a companion flying the mission: its MISSION_ITEM_REACHED
(routed on to the ground station, recorded here as events), and HOME_POSITION and
GPS_GLOBAL_ORIGIN when asked (MAV_CMD_REQUEST_MESSAGE). The SIM_MIS_DROP parameter: the
first SIM_MIS_DROP_N (default 1) answers for that item are lost, as on a lossy radio."""
from __future__ import annotations

import math

from pymavlink import mavutil

mavlink = mavutil.mavlink
EARTH_RADIUS = 6378137.0
HOME = (-35.3632621, 149.1652374, 584.09)   # lat, lon (deg), altitude AMSL (m): the local origin
MISSION = mavlink.MAV_MISSION_TYPE_MISSION


def global_of(p_enu, origin=HOME):
    """(lat, lon, alt AMSL) of a local ENU point, flat earth about the origin."""
    lat0, lon0, alt0 = origin
    lat = lat0 + math.degrees(p_enu[1] / EARTH_RADIUS)
    lon = lon0 + math.degrees(p_enu[0] / (EARTH_RADIUS * math.cos(math.radians(lat0))))
    return lat, lon, alt0 + p_enu[2]


class MissionStore:
    def __init__(self, conn, autopilot: str, event, params):
        self.conn, self.ap, self.event, self.params = conn, autopilot, event, params
        self.items = []             # the stored mission: MISSION_ITEM_INT messages
        self.current = 0
        self.upload = None          # (count, items so far, last request time) while one runs
        self.dropped = []            # the seqs of the answers lost (SIM_MIS_DROP)
        self.home_enu = (0.0, 0.0, 0.0)
        self.on_current = lambda seq: None   # the vehicle's: MISSION_SET_CURRENT taken (AUTO starts it)

    @property
    def first(self) -> int:
        return 1 if self.ap == "ardupilot" else 0

    def on_message(self, t: str, msg, now: float) -> bool:
        """Handles a mission message (True), or leaves it (False)."""
        if getattr(msg, "mission_type", MISSION) != MISSION and t.startswith("MISSION_"):
            if t in ("MISSION_REQUEST_LIST", "MISSION_COUNT"):
                self._ack(msg, mavlink.MAV_MISSION_UNSUPPORTED)
            return True
        handler = {"MISSION_COUNT": self._on_count, "MISSION_ITEM_INT": self._on_item,
                   "MISSION_REQUEST_LIST": self._on_request_list, "MISSION_REQUEST_INT": self._on_request,
                   "MISSION_REQUEST": self._on_request, "MISSION_SET_CURRENT": self._on_set_current,
                   "MISSION_CLEAR_ALL": self._on_clear, "MISSION_ITEM_REACHED": self._on_reached,
                   "MISSION_ACK": lambda m, n: None}.get(t)
        if handler is None:
            return False
        handler(msg, now)
        return True

    # ---- upload (a ground station's) ------------------------------------------------------
    def _on_count(self, m, now):
        if m.count == 0:
            return self._on_clear(m, now)
        self.upload = (m.count, [], now, (m.get_srcSystem(), m.get_srcComponent()))
        self._request(0, now)

    def _request(self, seq, now):
        count, items, _, src = self.upload
        self.upload = (count, items, now, src)
        self.conn.mav.mission_request_int_send(src[0], src[1], seq, MISSION)

    def _on_item(self, m, now):
        if self.upload is None:
            return
        count, items, _, src = self.upload
        if m.seq != len(items):
            return self._request(len(items), now)    # a repeat, or one ahead of a lost one
        items.append(m)
        if len(items) < count:
            return self._request(len(items), now)
        self.upload = None
        self.items, self.current = items, self.first
        self.conn.mav.mission_ack_send(src[0], src[1], mavlink.MAV_MISSION_ACCEPTED, MISSION)
        self.event("mission_uploaded", count=count)
        self.send_current()

    def tick(self, now):
        """Re-requests an upload's item unanswered for 1 s; MISSION_CURRENT at 1 Hz (the caller's)."""
        if self.upload is not None and now - self.upload[2] > 1.0:
            self._request(len(self.upload[1]), now)

    def _on_clear(self, m, now):
        self.items, self.current, self.upload = [], 0, None
        self._ack(m, mavlink.MAV_MISSION_ACCEPTED)
        self.event("mission_cleared")
        self.send_current()

    # ---- download (anyone's) --------------------------------------------------------------
    def _on_request_list(self, m, now):
        self.conn.mav.mission_count_send(m.get_srcSystem(), m.get_srcComponent(), len(self.items), MISSION)

    def _on_request(self, m, now):
        if not 0 <= m.seq < len(self.items):
            return self._ack(m, mavlink.MAV_MISSION_INVALID_SEQUENCE)
        if m.seq == int(self.params.get("SIM_MIS_DROP", -1)) and \
                self.dropped.count(m.seq) < int(self.params.get("SIM_MIS_DROP_N", 1)):
            self.dropped.append(m.seq)
            self.event("mission_item_dropped", seq=m.seq)
            return
        it = self.items[m.seq]
        self.conn.mav.mission_item_int_send(m.get_srcSystem(), m.get_srcComponent(), it.seq, it.frame, it.command,
                                            int(it.seq == self.current), it.autocontinue, it.param1, it.param2,
                                            it.param3, it.param4, it.x, it.y, it.z, MISSION)

    # ---- progress -------------------------------------------------------------------------
    def _on_set_current(self, m, now):
        if self.first <= m.seq < len(self.items):
            self.current = m.seq
            self.event("mission_set_current", seq=m.seq, src=m.get_srcComponent())
            self.on_current(m.seq)
        self.send_current()

    def _on_reached(self, m, now):
        self.event("mission_item_reached", seq=m.seq, src=m.get_srcComponent())

    def send_current(self):
        state = mavlink.MISSION_STATE_NO_MISSION if not self.items else mavlink.MISSION_STATE_NOT_STARTED
        # `total` leaves out a home stored as item 0, as ArduPilot's does (GCS_Common.cpp).
        self.conn.mav.mission_current_send(self.current, max(len(self.items) - self.first, 0), state, 0)

    def _ack(self, m, result):
        self.conn.mav.mission_ack_send(m.get_srcSystem(), m.get_srcComponent(), result, MISSION)

    # ---- home and origin ------------------------------------------------------------------
    def send_home(self):
        lat, lon, alt = global_of(self.home_enu)
        x, y, z = self.home_enu[1], self.home_enu[0], -self.home_enu[2]   # NED
        self.conn.mav.home_position_send(int(lat * 1e7), int(lon * 1e7), int(alt * 1000), x, y, z, [1, 0, 0, 0],
                                         0, 0, 0)

    def send_origin(self):
        lat, lon, alt = HOME
        self.conn.mav.gps_global_origin_send(int(lat * 1e7), int(lon * 1e7), int(alt * 1000))
