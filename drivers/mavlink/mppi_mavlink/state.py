"""Telemetry -> vehicle_state_t: ODOMETRY (PX4), or ATTITUDE_QUATERNION paired with the latest
LOCAL_POSITION_NED (ArduPilot; `vehicle.state_source`), converted NED/FRD -> ENU/FLU, every
value finite, numbered, and remembered by number (publish time, autopilot time) so that the
forwarding gate can tell how old the state a command answers is."""
from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict

from . import clock_sync, frames, telemetry
from .autopilots.base import mavlink


def mono_us() -> int:
    return time.monotonic_ns() // 1000


def wall_us() -> int:
    return time.time_ns() // 1000


def rotate(q, v):
    """v rotated by the unit quaternion q (w, x, y, z): R(q) v."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 q_vec x v; v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))


class StatePublisher:
    def __init__(self, settings, mppi_lcm, publish, counters):
        self.source = settings["vehicle"]["state_source"]
        self.channel = settings["lcm"]["state_channel"]
        self.mppi_lcm, self.publish, self.counters = mppi_lcm, publish, counters
        self.boot_clock = clock_sync.ClockSync()  # the autopilot's clock on ours, drift followed
        self.seq = 0
        self.times = OrderedDict()   # seq -> (monotonic us when published, MAVLink time_usec)
        self.last_odom_mono = None
        self.last_lpn = None
        self.lock = threading.Lock()
        self.rate = telemetry.StateRate(1.0)
        self.last_p = None           # ENU position of the latest state published

    def published(self, seq):
        """(monotonic us when published, the autopilot's time) of state `seq`, or None."""
        with self.lock:
            return self.times.get(seq)

    def on_message(self, t: str, msg) -> None:
        if t == "ODOMETRY":
            self._on_odometry(msg)
        elif t == "ATTITUDE_QUATERNION":
            self._on_attitude(msg)
        elif t == "LOCAL_POSITION_NED":
            self.last_lpn = (msg, wall_us())

    def _on_odometry(self, msg):
        if self.source == "split" or msg.frame_id not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD):
            return
        try:
            q_ned = frames.quat_normalize(tuple(msg.q))
        except ValueError:  # a zero or non-finite quaternion: no attitude, no state
            self.counters["states_rejected"] += 1
            return
        v = (msg.vx, msg.vy, msg.vz)
        if msg.child_frame_id in (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED):
            v = rotate(q_ned, v)  # ODOMETRY's velocity is in the child (body) frame
        self.last_odom_mono = time.monotonic()
        self._publish(msg.time_usec, (msg.x, msg.y, msg.z), v, q_ned, (msg.rollspeed, msg.pitchspeed, msg.yawspeed))

    def _on_attitude(self, msg):
        if self.source == "odometry":
            return
        if self.source == "auto" and self.last_odom_mono is not None and time.monotonic() - self.last_odom_mono < 0.5:
            return
        if self.last_lpn is None or wall_us() - self.last_lpn[1] > 200_000:
            return
        p = self.last_lpn[0]
        try:
            q_ned = frames.quat_normalize((msg.q1, msg.q2, msg.q3, msg.q4))
        except ValueError:
            self.counters["states_rejected"] += 1
            return
        self._publish(msg.time_boot_ms * 1000, (p.x, p.y, p.z), (p.vx, p.vy, p.vz), q_ned,
                      (msg.rollspeed, msg.pitchspeed, msg.yawspeed))

    def _publish(self, boot_us, p_ned, v_ned, q_ned, w_frd):
        x = (list(frames.ned_to_enu(p_ned)) + list(frames.ned_to_enu(v_ned)) + list(frames.q_ned_frd_to_enu_flu(q_ned))
             + list(frames.frd_to_flu(w_frd)))
        if not all(math.isfinite(c) for c in x):
            self.counters["states_rejected"] += 1
            return
        now_wall = wall_us()
        msg = self.mppi_lcm.vehicle_state_t()
        with self.lock:
            self.seq += 1
            msg.seq = self.seq
            self.times[msg.seq] = (mono_us(), boot_us)
            while len(self.times) > 256:
                self.times.popitem(last=False)
        msg.utime = now_wall
        msg.sample_utime = self.boot_clock.update(int(boot_us), now_wall)
        msg.model = self.mppi_lcm.vehicle_state_t.MODEL_QUADROTOR_RATE
        msg.vehicle_count = 1
        msg.nx = 13
        msg.n = 13
        msg.x = x
        self.publish(self.channel, msg.encode())
        self.last_p = tuple(x[0:3])
        self.counters["states_published"] += 1
        self.rate.add(time.monotonic())
