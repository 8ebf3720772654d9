"""The referee of a flight through ArduCopter SITL: a second MAVLink link (the SITL's second
serial port) that records what the simulation knows and the autopilot says, to truth.jsonl.

ArduPilot's SITL reports its simulated truth in SIM_STATE (position as latitude, longitude
and altitude; NED velocity; attitude quaternion), which the bridge never sees. Each line:
    {"boot_us", "wall_us", "x": [e, n, u] true position in the local ENU frame of the EKF's
     origin, "v": true ENU velocity, "tilt_deg", "est": the autopilot's estimate
     (LOCAL_POSITION_NED, ENU), "mode", "armed"}
boot_us is the autopilot's clock: the LOCAL_POSITION_NED sent in the same burst as the SIM_STATE
(ArduPilot sends a stream bucket's messages in ap_message order, SIM_STATE before
LOCAL_POSITION_NED), so "x" and "est" are of the same time; a record is written when that
position comes ("paired": true; a SIM_STATE with no position after it is written with the one
before, "paired": false, boot_us then the estimate's time). Before 2026-11-26 each record held the previous
burst's estimate, 20 ms older than the truth beside it. wall_us this host's, at the SIM_STATE's
receipt. Events: {"event": "mode"|"armed"|"disarmed"|"statustext"|
"origin", ...}. The local frame's origin is GPS_GLOBAL_ORIGIN once the EKF has one (asked
for), else the --home given to the SITL.

With --lcm-url (a sensed mission: the sensors' bus), each paired truth is also published, once
the EKF's origin is known, as vehicle_state_t on SIM_TRUTH for mppid-sensors (truth_bus.py: the
frame above, the bridge's), sampled at the autopilot's time of its burst mapped onto this host's
wall clock as the referee's score maps it (boot time + the smallest receipt delay seen so far):
the clock of mppid's states.

    python -m sitl_harness.ap_truth --url tcp:127.0.0.1:5762 --home LAT,LON,ALT --out DIR [--lcm-url URL]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from mppi_mavlink import frames  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from .truth_bus import TruthPublisher  # noqa: E402

mavlink = mavutil.mavlink
# ArduPilot's Location: metres per 1e-7 degree of latitude (LOCATION_SCALING_FACTOR).
M_PER_E7 = 0.011131884502145034
STREAMS = ((mavlink.MAVLINK_MSG_ID_SIM_STATE, 50.0), (mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 50.0),
           (mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 2.0))


def connect(url: str, timeout: float = 60.0):
    """A MAVLink connection, retried while the SITL is still starting to listen."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return mavutil.mavlink_connection(url, source_system=253, source_component=191, autoreconnect=True)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def to_local(lat_e7: int, lon_e7: int, alt_m: float, origin) -> list[float]:
    """ENU metres from the origin (lat e7, lon e7, alt m), as ArduPilot's Location does."""
    olat, olon, oalt = origin
    n = (lat_e7 - olat) * M_PER_E7
    e = (lon_e7 - olon) * M_PER_E7 * math.cos(math.radians(olat * 1e-7))
    return [e, n, alt_m - oalt]


class Recorder:
    truth_out: TruthPublisher | None = None
    have_origin = False
    position_wall_us = 0  # this host's wall clock at the newest LOCAL_POSITION_NED's receipt

    def __init__(self, url: str, home, out: Path, lcm_url: str | None = None):
        self.conn = connect(url)
        self.truth_out = TruthPublisher(lcm_url) if lcm_url else None
        self.origin = (int(home[0] * 1e7), int(home[1] * 1e7), float(home[2]))
        self.f = open(out / "truth.jsonl", "w", buffering=1)
        self.boot_us = 0
        self.est = None
        self.truth = None  # (SIM_STATE, wall us at receipt), awaiting the position of its burst
        self.mode, self.armed = "", False
        self.have_origin = False
        self.next_origin_ask = 0.0

    def _write_truth(self, paired: bool):
        if self.truth is None:
            return
        m, wall = self.truth
        self.truth = None
        q = (m.q1, m.q2, m.q3, m.q4)
        x = to_local(m.lat_int, m.lon_int, m.alt, self.origin)
        if paired and self.truth_out is not None and self.have_origin:
            self.truth_out.publish(x, (m.ve, m.vn, -m.vd), q, (m.xgyro, m.ygyro, m.zgyro),
                                   self.truth_out.clock(self.boot_us, self.position_wall_us))
        self.f.write(json.dumps({
            "boot_us": self.boot_us, "paired": paired, "wall_us": wall,
            "x": [round(c, 4) for c in x],
            "v": [round(m.ve, 4), round(m.vn, 4), round(-m.vd, 4)], "tilt_deg": round(frames.tilt_deg(q), 2),
            "est": None if self.est is None else [round(c, 4) for c in self.est],
            "mode": self.mode, "armed": self.armed}) + "\n")

    def event(self, what, **kw):
        self.f.write(json.dumps({"event": what, "wall_us": time.time_ns() // 1000, "boot_us": self.boot_us,
                                 **kw}) + "\n")

    def ask_streams(self):
        for mid, hz in STREAMS:
            self.conn.mav.command_long_send(self.conn.target_system, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                            mid, 1e6 / hz, 0, 0, 0, 0, 0)

    def run(self, stop):
        self.conn.wait_heartbeat(timeout=120)
        self.ask_streams()
        self.event("link", system=self.conn.target_system)
        print(json.dumps({"event": "ready"}), flush=True)
        while not stop():
            if not self.have_origin and time.monotonic() > self.next_origin_ask:
                self.next_origin_ask = time.monotonic() + 2.0
                self.conn.mav.command_long_send(self.conn.target_system, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                                mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0, 0, 0, 0, 0, 0)
            msg = self.conn.recv_match(blocking=True, timeout=0.2)
            if msg is not None:
                self.handle(msg)

    def handle(self, m):
        t = m.get_type()
        if t == "LOCAL_POSITION_NED":
            self.boot_us = m.time_boot_ms * 1000
            self.position_wall_us = time.time_ns() // 1000
            self.est = list(frames.ned_to_enu((m.x, m.y, m.z)))
            self._write_truth(True)
        elif t == "SIM_STATE":
            self._write_truth(False)  # one never followed by a position: with the one before
            self.truth = (m, time.time_ns() // 1000)
        elif t == "HEARTBEAT" and m.get_srcComponent() == 1 and m.type != mavlink.MAV_TYPE_GCS:
            mode = mavutil.mode_string_v10(m)
            armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if mode != self.mode:
                self.event("mode", mode=mode, previous=self.mode)
                self.mode = mode
            if armed != self.armed:
                self.event("armed" if armed else "disarmed")
                self.armed = armed
        elif t == "GPS_GLOBAL_ORIGIN" and not self.have_origin:
            self.origin = (m.latitude, m.longitude, m.altitude / 1000.0)
            self.have_origin = True
            self.event("origin", lat_e7=m.latitude, lon_e7=m.longitude, alt_m=m.altitude / 1000.0)
        elif t == "STATUSTEXT":
            self.event("statustext", text=m.text.rstrip("\x00") if isinstance(m.text, str) else str(m.text))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="ap_truth", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="tcp:127.0.0.1:5762")
    ap.add_argument("--home", required=True, help="LAT,LON,ALT[,HDG] as given to the SITL")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--lcm-url", help="publish the truth (vehicle_state_t on SIM_TRUTH) on this bus")
    a = ap.parse_args(argv)
    home = [float(c) for c in a.home.split(",")[:3]]
    done = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.append(1))
    rec = Recorder(a.url, home, a.out, a.lcm_url)
    try:
        rec.run(lambda: bool(done))
    finally:
        rec.f.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
