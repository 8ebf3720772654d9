"""The referee of a flight through PX4 SITL with SIH (flights/px4.py): what SIH knows and
what PX4 says, recorded to truth_raw.jsonl (px4_score.py turns it into truth.jsonl, the
format ap_truth.py writes for ArduCopter, once the flight is over).

PX4 sends SIH's ground truth (the `vehicle_*_groundtruth` topics) to the SIH display port as
HIL_STATE_QUATERNION (geodetic position, NED velocity, attitude; `time_usec` on PX4's
clock), and its estimate, mode and messages to the GCS port (LOCAL_POSITION_NED, HEARTBEAT,
STATUSTEXT). The bridge (or the offboard baseline) never sees either port. Lines:
    {"truth": 1, "boot_us", "wall_us", "lat", "lon" (1e-7 deg), "alt" (mm AMSL), "v" (ENU m/s),
     "q" (w, x, y, z, NED/FRD)}
    {"est": [e, n, u], "boot_us", "wall_us"}          (LOCAL_POSITION_NED, ENU)
    {"event": "mode"|"armed"|"disarmed"|"statustext"|"origin", "wall_us", ...}
The origin is GPS_GLOBAL_ORIGIN (the estimator's local frame), asked for on the GCS link.

    python -m sitl_harness.px4_truth --out DIR [--truth-port 19410] [--gcs-port 14550]
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
from pymavlink import mavutil  # noqa: E402

mavlink = mavutil.mavlink
TRUTH_PORT = 19410   # PX4's SIH display link (px4-rc.mavlink): HIL_STATE_QUATERNION
GCS_PORT = 14550     # PX4's GCS link
# PX4's modes by (main, sub) of the custom mode (px4_custom_mode.h); LAND as ArduPilot's, so
# ap_score's crash check stops where the landing begins.
MODES = {(1, 0): "MANUAL", (2, 0): "ALTCTL", (3, 0): "POSCTL", (4, 2): "TAKEOFF", (4, 3): "HOLD",
         (4, 4): "MISSION", (4, 5): "RTL", (4, 6): "LAND", (5, 0): "ACRO", (6, 0): "OFFBOARD",
         (7, 0): "STABILIZED", (4, 7): "RTGS", (4, 8): "FOLLOW", (4, 9): "PRECLAND"}


def px4_mode(custom_mode: int) -> str:
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    return MODES.get((main, sub if main == 4 else 0), f"{main}.{sub}")


class Recorder:
    def __init__(self, out: Path, truth_port: int, gcs_port: int):
        self.f = open(out / "truth_raw.jsonl", "w", buffering=1)
        self.lock = threading.Lock()
        self.truth = mavutil.mavlink_connection(f"udpin:127.0.0.1:{truth_port}", source_system=253)
        self.gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{gcs_port}", source_system=253,
                                              source_component=191)
        self.mode, self.armed, self.have_origin = "", False, False

    def write(self, doc: dict):
        doc["wall_us"] = time.time_ns() // 1000
        with self.lock:
            self.f.write(json.dumps(doc) + "\n")

    def run_truth(self, stop):
        said = False
        while not stop():
            m = self.truth.recv_match(type="HIL_STATE_QUATERNION", blocking=True, timeout=0.2)
            if m is None:
                continue
            if not said:
                print(json.dumps({"event": "ready"}), flush=True)
                said = True
            self.write({"truth": 1, "boot_us": m.time_usec, "lat": m.lat, "lon": m.lon, "alt": m.alt,
                        "v": [c / 100.0 for c in frames.ned_to_enu((m.vx, m.vy, m.vz))],
                        "q": [round(c, 6) for c in m.attitude_quaternion]})

    def run_gcs(self, stop):
        next_ask = 0.0
        while not stop():
            if not self.have_origin and self.gcs.target_system and time.monotonic() > next_ask:
                next_ask = time.monotonic() + 2.0
                self.gcs.mav.command_long_send(self.gcs.target_system, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                               mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0, 0, 0, 0, 0, 0)
            m = self.gcs.recv_match(blocking=True, timeout=0.2)
            if m is not None:
                self.handle(m)

    def handle(self, m):
        t = m.get_type()
        if t == "LOCAL_POSITION_NED":
            self.write({"est": [round(c, 4) for c in frames.ned_to_enu((m.x, m.y, m.z))], "boot_us": m.time_boot_ms * 1000})
        elif t == "HEARTBEAT" and m.get_srcComponent() == 1 and m.autopilot == mavlink.MAV_AUTOPILOT_PX4:
            mode, armed = px4_mode(m.custom_mode), bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if mode != self.mode:
                self.write({"event": "mode", "mode": mode, "previous": self.mode})
                self.mode = mode
            if armed != self.armed:
                self.write({"event": "armed" if armed else "disarmed"})
                self.armed = armed
        elif t == "GPS_GLOBAL_ORIGIN" and not self.have_origin:
            self.have_origin = True
            self.write({"event": "origin", "lat_e7": m.latitude, "lon_e7": m.longitude, "alt_mm": m.altitude})
        elif t == "STATUSTEXT":
            self.write({"event": "statustext", "text": m.text.rstrip("\x00") if isinstance(m.text, str)
                        else str(m.text), "severity": m.severity})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="px4_truth", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--truth-port", type=int, default=TRUTH_PORT)
    ap.add_argument("--gcs-port", type=int, default=GCS_PORT)
    a = ap.parse_args(argv)
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())
    rec = Recorder(a.out, a.truth_port, a.gcs_port)
    gcs = threading.Thread(target=rec.run_gcs, args=(done.is_set,), name="gcs", daemon=True)
    gcs.start()
    try:
        rec.run_truth(done.is_set)
    finally:
        done.set()
        gcs.join(1.0)
        rec.f.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
