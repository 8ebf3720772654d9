"""The vehicle's recent poses from vehicle_state_t (the rate quadrotor's layout, as the MAVLink
bridge publishes: position ENU at 0..2, the attitude quaternion body FLU -> ENU at 6..9), and a
frame's pose: the state sampled nearest the frame's time, within max_age."""
from __future__ import annotations

import bisect
import math
import threading
from collections import Counter

RATE_NX, PX, QW = 13, 0, 6


class StateHistory:
    """The last `keep` states' (sample time, position, quaternion), newest last; thread-safe
    (states arrive on LCM's thread, frames on the camera's)."""

    def __init__(self, model_rate: int, vehicle: int, max_age_s: float, keep: int = 256):
        self.model_rate, self.vehicle, self.keep = model_rate, vehicle, keep
        self.max_age_us = int(max_age_s * 1e6)
        self.times: list[int] = []
        self.poses: list[tuple] = []
        self.refused = Counter()
        self.taken = 0
        self._lock = threading.Lock()
        self.first = threading.Event()

    def on_state(self, m) -> bool:
        """A decoded vehicle_state_t; False (and counted) when it cannot give a pose."""
        if m.model != self.model_rate or m.nx != RATE_NX or m.n != m.nx * m.vehicle_count or len(m.x) != m.n:
            self.refused["layout"] += 1
            return False
        if not 0 <= self.vehicle < m.vehicle_count:
            self.refused["vehicle"] += 1
            return False
        x = m.x[self.vehicle * RATE_NX:(self.vehicle + 1) * RATE_NX]
        p, q = x[PX:PX + 3], x[QW:QW + 4]
        qn = math.sqrt(sum(c * c for c in q)) if all(math.isfinite(c) for c in q) else float("nan")
        if not all(math.isfinite(c) for c in p) or not abs(qn - 1.0) < 0.01:
            self.refused["not_finite"] += 1
            return False
        with self._lock:
            if self.times and m.sample_utime <= self.times[-1]:
                self.refused["out_of_order"] += 1
                return False
            self.times.append(int(m.sample_utime))
            self.poses.append((tuple(p), tuple(c / qn for c in q)))
            if len(self.times) > self.keep:
                del self.times[0], self.poses[0]
            self.taken += 1
        self.first.set()
        return True

    def pose_at(self, utime: int):
        """(position, quaternion) of the state sampled nearest `utime`, or None when none is
        within max_age of it."""
        with self._lock:
            i = bisect.bisect_left(self.times, utime)
            best = None
            for j in (i - 1, i):
                if 0 <= j < len(self.times) and (best is None or abs(self.times[j] - utime) < abs(self.times[best] - utime)):
                    best = j
            if best is None or abs(self.times[best] - utime) > self.max_age_us:
                return None
            return self.poses[best]
