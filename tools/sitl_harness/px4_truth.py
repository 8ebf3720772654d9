"""The referee of a flight through PX4 SITL with SIH (flights/px4.py): what SIH knows and
what PX4 says, recorded to truth_raw.jsonl (px4_score.py turns it into truth.jsonl, the
format ap_truth.py writes for ArduCopter, once the flight is over).

All of it on one link the bridge (or the offboard baseline) never sees: PX4's SIH display link
(px4-rc.mavlink: PX4 listens on 19450 and sends to 19410). PX4 sends it SIH's ground truth (the
`vehicle_*_groundtruth` topics) as HIL_STATE_QUATERNION (geodetic position, NED velocity,
attitude, body rates; `time_usec` on PX4's clock; 25 Hz as PX4 starts it, `--truth-hz` asks for
another rate), HEARTBEAT and STATUSTEXT as on every link; the referee asks it for
LOCAL_POSITION_NED (PX4's estimate, 50 Hz) and GPS_GLOBAL_ORIGIN (the estimator's local frame)
by MAV_CMD_SET_MESSAGE_INTERVAL / MAV_CMD_REQUEST_MESSAGE, again every 2 s until they come.
The messages (STATUSTEXT) come from PX4's GCS link (PX4 sends it to 14550): PX4 forwards the
bridge's there too, not to the display link. The referee sends it one request as PX4 is heard
there, which makes it the link's partner, as a ground station is: PX4's UDP link answers the
first sender, and another one (px4_faults.py's mode change) would otherwise take the link's
messages away. With --gcs-port 0 a ground station has that port (ap_gcs.py uploads a survey
there) and the display link's (PX4's own) are recorded. Lines:
    {"truth": 1, "boot_us", "wall_us", "lat", "lon" (1e-7 deg), "alt" (mm AMSL), "v" (ENU m/s),
     "q" (w, x, y, z, NED/FRD)}
    {"est": [e, n, u], "boot_us", "wall_us"}          (LOCAL_POSITION_NED, ENU)
    {"event": "mode"|"armed"|"disarmed"|"statustext"|"origin", "wall_us", ...}

With --lcm-url (a sensed mission: the sensors' bus), each truth is also published, once the
estimator's origin is known, as vehicle_state_t on SIM_TRUTH for mppid-sensors (truth_bus.py):
SIH's position projected as PX4 projects GPS (px4_score.project) about that origin, the frame of
mppid's states and the mission's trees; its time PX4's boot clock mapped onto this host's wall
clock by mppi_mavlink.clock_sync, as the bridge maps the states' (SIH's clock runs ~1 % slow).

    python -m sitl_harness.px4_truth --out DIR [--truth-port 19410] [--gcs-port 14550|0] [--truth-hz HZ]
        [--lcm-url URL]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from mppi_mavlink import frames  # noqa: E402
from mppi_mavlink.clock_sync import ClockSync  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from .px4_score import project  # noqa: E402
from .truth_bus import TruthPublisher  # noqa: E402

mavlink = mavutil.mavlink
TRUTH_PORT = 19410   # PX4's SIH display link sends here (px4-rc.mavlink)
GCS_PORT = 14550     # PX4's GCS link sends here
ESTIMATE_HZ = 50.0   # LOCAL_POSITION_NED asked for (the rate PX4's GCS link streams it at)
ASK_EVERY_S = 2.0
# PX4's modes by (main, sub) of the custom mode (px4_custom_mode.h); LAND as ArduPilot's, so
# ap_score's crash check stops where the landing begins.
MODES = {(1, 0): "MANUAL", (2, 0): "ALTCTL", (3, 0): "POSCTL", (4, 2): "TAKEOFF", (4, 3): "HOLD",
         (4, 4): "MISSION", (4, 5): "RTL", (4, 6): "LAND", (5, 0): "ACRO", (6, 0): "OFFBOARD",
         (7, 0): "STABILIZED", (4, 7): "RTGS", (4, 8): "FOLLOW", (4, 9): "PRECLAND"}


def px4_mode(custom_mode: int) -> str:
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    return MODES.get((main, sub if main == 4 else 0), f"{main}.{sub}")


class Recorder:
    def __init__(self, out: Path, truth_port: int, truth_hz: float | None = None, lcm_url: str | None = None,
                 gcs_port: int = 0):
        self.f = open(out / "truth_raw.jsonl", "w", buffering=1)
        self.lock = threading.Lock()
        self.link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{truth_port}", source_system=253,
                                               source_component=191)
        self.gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{gcs_port}", source_system=253,
                                              source_component=191) if gcs_port else None
        self.truth_hz = truth_hz
        self.truth_out = TruthPublisher(lcm_url) if lcm_url else None
        self.sync = ClockSync()
        self.mode, self.armed, self.origin, self.have_est = "", False, None, False
        self.said_ready = False
        self.next_ask = 0.0

    def write(self, doc: dict, wall_us: int | None = None):
        doc["wall_us"] = time.time_ns() // 1000 if wall_us is None else wall_us
        with self.lock:
            self.f.write(json.dumps(doc) + "\n")

    def _command(self, cmd: int, *params):
        self.link.mav.command_long_send(1, 1, cmd, 0, *(list(params) + [0] * (7 - len(params))))

    def ask(self):
        """The streams and the origin, until they come (PX4 starts the link streaming nothing of them)."""
        if not self.have_est:
            self._command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                          1e6 / ESTIMATE_HZ)
            if self.truth_hz:
                self._command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION,
                              1e6 / self.truth_hz)
        if self.origin is None:
            self._command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)

    def run(self, stop):
        while not stop():
            m = self.link.recv_match(blocking=True, timeout=0.2)
            if self.said_ready and (not self.have_est or self.origin is None) and time.monotonic() > self.next_ask:
                self.next_ask = time.monotonic() + ASK_EVERY_S
                self.ask()   # PX4's address is known once it has sent (the first truth)
            if m is not None:
                self.handle(m)

    def handle(self, m, wall_us: int | None = None):
        t = m.get_type()
        wall_us = time.time_ns() // 1000 if wall_us is None else wall_us
        if t == "HIL_STATE_QUATERNION":
            self.on_truth(m, wall_us)
        elif t == "LOCAL_POSITION_NED":
            self.have_est = True
            self.write({"est": [round(c, 4) for c in frames.ned_to_enu((m.x, m.y, m.z))],
                        "boot_us": m.time_boot_ms * 1000}, wall_us)
        elif t == "HEARTBEAT" and m.get_srcComponent() == 1 and m.autopilot == mavlink.MAV_AUTOPILOT_PX4:
            mode, armed = px4_mode(m.custom_mode), bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if mode != self.mode:
                self.write({"event": "mode", "mode": mode, "previous": self.mode}, wall_us)
                self.mode = mode
            if armed != self.armed:
                self.write({"event": "armed" if armed else "disarmed"}, wall_us)
                self.armed = armed
        elif t == "GPS_GLOBAL_ORIGIN" and self.origin is None:
            self.origin = (m.latitude, m.longitude, m.altitude)
            self.write({"event": "origin", "lat_e7": m.latitude, "lon_e7": m.longitude, "alt_mm": m.altitude}, wall_us)
        elif t == "STATUSTEXT" and self.gcs is None:
            self.text(m, wall_us)

    def text(self, m, wall_us: int | None = None):
        self.write({"event": "statustext", "text": m.text.rstrip("\x00") if isinstance(m.text, str)
                    else str(m.text), "severity": m.severity}, wall_us)

    def run_texts(self, stop):
        """PX4's GCS link's STATUSTEXT (its own and those it forwards); the link claimed once."""
        claimed = False
        while not stop():
            m = self.gcs.recv_match(blocking=True, timeout=0.2)
            if m is None:
                continue
            if not claimed:
                self.gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                               mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0, 0, 0, 0, 0, 0)
                claimed = True
            if m.get_type() == "STATUSTEXT":
                self.text(m)

    def on_truth(self, m, wall_us: int):
        if not self.said_ready:
            print(json.dumps({"event": "ready"}), flush=True)
            self.said_ready = True
        v = [c / 100.0 for c in frames.ned_to_enu((m.vx, m.vy, m.vz))]
        self.write({"truth": 1, "boot_us": m.time_usec, "lat": m.lat, "lon": m.lon, "alt": m.alt, "v": v,
                    "q": [round(c, 6) for c in m.attitude_quaternion]}, wall_us)
        sample_us = self.sync.update(int(m.time_usec), wall_us)
        if self.truth_out is not None and self.origin is not None:
            lat0, lon0, alt0 = self.origin
            north, east = project(m.lat, m.lon, lat0, lon0)
            self.truth_out.publish((float(east), float(north), (m.alt - alt0) * 1e-3), v, m.attitude_quaternion,
                                   (m.rollspeed, m.pitchspeed, m.yawspeed), sample_us)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="px4_truth", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--truth-port", type=int, default=TRUTH_PORT)
    ap.add_argument("--gcs-port", type=int, default=GCS_PORT,
                    help="PX4's GCS link, for its messages (0: a ground station has it; the display link's)")
    ap.add_argument("--truth-hz", type=float, help="ask PX4 for SIH's truth at this rate (PX4 starts it at 25 Hz)")
    ap.add_argument("--lcm-url", help="publish the truth (vehicle_state_t on SIM_TRUTH) on this bus")
    a = ap.parse_args(argv)
    if a.truth_hz is not None and not 1.0 <= a.truth_hz <= 250.0:
        ap.error(f"--truth-hz {a.truth_hz:g}: 1 to 250 (SIH's loop)")
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())
    rec = Recorder(a.out, a.truth_port, a.truth_hz, a.lcm_url, a.gcs_port)
    texts = threading.Thread(target=rec.run_texts, args=(done.is_set,), daemon=True) if rec.gcs else None
    if texts:
        texts.start()
    try:
        rec.run(done.is_set)
    finally:
        done.set()
        if texts:
            texts.join(1.0)
        rec.f.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
