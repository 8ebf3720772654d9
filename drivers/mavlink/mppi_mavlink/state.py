"""Telemetry -> vehicle_state_t: ODOMETRY (PX4), or ATTITUDE_QUATERNION paired with the
LOCAL_POSITION_NED of the same time (ArduPilot; `vehicle.state_source`), converted NED/FRD ->
ENU/FLU, every value finite, numbered, and remembered by number (publish time, autopilot time)
so that the forwarding gate can tell how old the state a command answers is.

Times: `sample_utime` is when the autopilot's estimate was valid (its time_boot_ms / time_usec
mapped onto this host's wall clock by clock_sync), `utime` when the bridge published it.

The pair: ArduPilot sends a slot's ATTITUDE_QUATERNION *before* its LOCAL_POSITION_NED (its
message ids are sent in ap_message order within a stream bucket), so the position held when an
attitude arrives is the previous slot's, a period (20 ms at 50 Hz) older than the attitude it
would be stamped with. The bridge learns the order: when positions follow their attitudes, an
attitude waits for its position (microseconds, the same burst) and the pair is published on the
position; when they come first (the simulated autopilot), on the attitude. A position of
another time (streams at other rates) is carried to the attitude's time along its velocity."""
from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict

from . import clock_sync, frames, telemetry
from .autopilots.base import mavlink
from .layout import QuadrotorRate as Q


PAIR_MS = 2                    # an attitude and a position this close in time_boot_ms are one sample
MAX_POSITION_AGE_MS = 200      # no position for this long (the autopilot's time): no state


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
        self.times = OrderedDict()   # seq -> published(seq)
        self.last_odom_mono = None
        self.last_lpn = None         # (LOCAL_POSITION_NED, wall us at arrival)
        self.pending_att = None      # (ATTITUDE_QUATERNION, wall us at arrival) awaiting its position
        self.lpn_after = False       # positions follow their attitudes (ArduPilot's order)
        self.last_att_ms = None      # time_boot_ms of the attitude published last
        self.lock = threading.Lock()
        self.rate = telemetry.StateRate(1.0)
        self.last_p = None           # ENU position of the latest state published
        self.on_published = None     # f(the autopilot's time [us], x): the map to the autopilot's ticks

    def published(self, seq):
        """(monotonic us when published, the autopilot's time, monotonic us when its sample arrived,
        monotonic us when the LCM publish returned) of state `seq`, or None."""
        with self.lock:
            return self.times.get(seq)

    def on_message(self, t: str, msg) -> None:
        if t == "ODOMETRY":
            self._on_odometry(msg)
        elif t == "ATTITUDE_QUATERNION":
            self._on_attitude(msg)
        elif t == "LOCAL_POSITION_NED":
            self._on_position(msg)

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
        now = wall_us()
        lpn = self.last_lpn
        if lpn is not None and abs(msg.time_boot_ms - lpn[0].time_boot_ms) <= PAIR_MS:
            self.lpn_after = False  # its position came first
            self._publish_pair((msg, now), lpn[0])
            return
        if self.pending_att is not None:  # the one before never got its position: stop waiting
            self.lpn_after = False
            self.counters["states_rejected"] += 1
        self.pending_att = None
        if self.lpn_after:
            self.pending_att = (msg, now)  # its position follows in the same burst
            return
        if lpn is not None and 0 <= msg.time_boot_ms - lpn[0].time_boot_ms <= MAX_POSITION_AGE_MS:
            self._publish_pair((msg, now), lpn[0])

    def _on_position(self, msg):
        self.last_lpn = (msg, wall_us())
        att = self.pending_att
        if att is not None and abs(att[0].time_boot_ms - msg.time_boot_ms) <= PAIR_MS:
            self.pending_att = None
            self._publish_pair(att, msg)
        elif self.last_att_ms is not None and 0 <= msg.time_boot_ms - self.last_att_ms <= PAIR_MS:
            self.lpn_after = True   # the attitude published last came first: wait for positions from now on

    def _publish_pair(self, att, p):
        """An attitude and a position: the position carried along its velocity to the attitude's time."""
        msg, recv = att
        try:
            q_ned = frames.quat_normalize((msg.q1, msg.q2, msg.q3, msg.q4))
        except ValueError:
            self.counters["states_rejected"] += 1
            return
        gap_ms = msg.time_boot_ms - p.time_boot_ms
        dt = gap_ms * 1e-3 if 0 < gap_ms <= MAX_POSITION_AGE_MS else 0.0
        self.last_att_ms = msg.time_boot_ms
        self._publish(msg.time_boot_ms * 1000, (p.x + p.vx * dt, p.y + p.vy * dt, p.z + p.vz * dt),
                      (p.vx, p.vy, p.vz), q_ned, (msg.rollspeed, msg.pitchspeed, msg.yawspeed), recv)

    def _publish(self, boot_us, p_ned, v_ned, q_ned, w_frd, recv_wall=None):
        x = (list(frames.ned_to_enu(p_ned)) + list(frames.ned_to_enu(v_ned)) + list(frames.q_ned_frd_to_enu_flu(q_ned))
             + list(frames.frd_to_flu(w_frd)))
        if not all(math.isfinite(c) for c in x):
            self.counters["states_rejected"] += 1
            return
        now_wall, now_mono = wall_us(), mono_us()
        recv_wall = now_wall if recv_wall is None else recv_wall
        msg = self.mppi_lcm.vehicle_state_t()
        with self.lock:
            self.seq += 1
            msg.seq = self.seq
            self.times[msg.seq] = (now_mono, boot_us, now_mono - (now_wall - recv_wall))
            while len(self.times) > 256:
                self.times.popitem(last=False)
        msg.utime = now_wall
        # The clock is fitted on when the sample arrived (an attitude waits for its position)
        msg.sample_utime = self.boot_clock.update(int(boot_us), recv_wall)
        msg.model = self.mppi_lcm.vehicle_state_t.MODEL_QUADROTOR_RATE
        msg.vehicle_count = 1
        msg.nx = len(Q.STATE)
        msg.n = len(Q.STATE)
        msg.x = x
        self.publish(self.channel, msg.encode())
        with self.lock:
            self.times[msg.seq] += (mono_us(),)  # after the LCM publish
        self.last_p = tuple(x[Q.POS])
        self.counters["states_published"] += 1
        self.rate.add(time.monotonic())
        if self.on_published is not None:
            self.on_published(int(boot_us), x)
