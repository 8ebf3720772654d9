"""The autopilot's clock on this machine's: when a MAVLink sample was taken, in our time.

An autopilot stamps its telemetry with its own clock (`time_boot_ms`, `time_usec` since
boot). mppid judges a state's age from its `sample_utime` on this machine's wall clock, so the
bridge maps one onto the other. The two clocks do not run at the same rate: a crystal drifts
by tens of ppm, and PX4's SIH in lock-step ran 0.7 % slow on a loaded 2-core machine (0.18 s
behind after 25 s). A mapping fixed once (or relaxed by 100 us/s, the bridge's first one)
makes every state look older by the second, until mppid holds its plan for good.

The model: receive = a + (1 + skew) * autopilot + delay, with delay >= 0 (transport and
scheduling). Over each `window_s` of autopilot time the least-delayed sample (the minimum of
receive - autopilot) is kept. The skew is the least-squares slope of the last `windows`
minima (20 s: a long baseline), clamped to +-`max_skew`; the line is then lowered onto the
lowest of the last `envelope` minima (a lower envelope that forgets a longer route or a
paused clock within a few windows). A sample maps onto the line, and never later than its
own receive time. Until two windows are closed the line runs through the running minimum, with the skew
found before (none at the first start).
Bounded jumps: once fitted, a refit moves the mapped time by at most `max_step_us` (the rest
follows at the next windows); the estimator starts over when the autopilot's clock jumps
(back by more than `reset_s`: a reboot; or a sample arriving `reset_s` before the line
allows) or stood still (a whole window whose least delay is `reset_s` above the line).

Every time is in integer microseconds. `update` is O(1) except at a window's close (a fit
over `windows` points, once per `window_s`).
"""
from __future__ import annotations

from collections import deque


class ClockSync:
    def __init__(self, window_s: float = 1.0, windows: int = 20, envelope: int = 3, max_skew: float = 0.05,
                 max_step_us: int = 5000, reset_s: float = 1.0):
        if window_s <= 0 or windows < 2 or not 1 <= envelope <= windows or max_skew < 0 or max_step_us <= 0 \
                or reset_s <= 0:
            raise ValueError("clock_sync: window_s > 0, windows >= 2, 1 <= envelope <= windows, max_skew >= 0, "
                             "max_step_us > 0, reset_s > 0")
        self.window_us = int(window_s * 1e6)
        self.envelope = int(envelope)
        self.max_skew = float(max_skew)
        self.max_step_us = int(max_step_us)
        self.reset_us = int(reset_s * 1e6)
        self.minima: deque[tuple[int, int]] = deque(maxlen=windows)  # (autopilot us, receive - autopilot)
        self.resets = 0
        self.skew = 0.0
        self._start()

    def _start(self):
        """Forget the offset; the skew (the clocks' rates) is kept: a reboot does not change it."""
        self.minima.clear()
        self.bin_start = None         # autopilot time the open window began
        self.bin_min = None           # (autopilot us, receive - autopilot), the least-delayed in it
        self.ref, self.a = 0, None    # the line: offset(t) = a + skew * (t - ref)
        self.fitted = False           # the line is a fit (else through the running minimum)
        self.last_ap = None

    def offset_at(self, ap_us: int) -> float:
        """receive - autopilot for a sample taken at `ap_us` and sent with the least delay."""
        return self.a + self.skew * (ap_us - self.ref)

    def update(self, ap_us: int, recv_us: int) -> int:
        """One sample: the autopilot's stamp and when it arrived (this machine's clock, us).
        Returns when it was taken, on this machine's clock."""
        ap_us, recv_us = int(ap_us), int(recv_us)
        d = recv_us - ap_us
        if self._jumped(ap_us, d):
            self.resets += 1
            self._start()
        self.last_ap = ap_us
        if self.bin_start is None:
            self.bin_start = ap_us
        if self.bin_min is None or d < self.bin_min[1]:
            self.bin_min = (ap_us, d)
        if not self.fitted and (self.a is None or d < self.offset_at(ap_us)):
            self.ref, self.a = ap_us, float(d)
        if ap_us - self.bin_start >= self.window_us:
            self._close_window()
        return min(recv_us, int(round(ap_us + self.offset_at(ap_us))))

    def _jumped(self, ap_us: int, d: int) -> bool:
        """The autopilot rebooted (its clock went back), or its clock jumped ahead."""
        if self.last_ap is None:
            return False
        return ap_us < self.last_ap - self.reset_us or d < self.offset_at(ap_us) - self.reset_us

    def _close_window(self):
        t, d = self.bin_min
        if d > self.offset_at(t) + self.reset_us:  # a whole window late: the autopilot's clock stood still
            self.resets += 1
            self._start()
            self.ref, self.a, self.last_ap = t, float(d), t
        self.minima.append((t, d))
        self.bin_start, self.bin_min = self.last_ap, None
        if len(self.minima) < 2:
            return
        skew = self._fit_skew()
        ref = self.minima[-1][0]
        recent = list(self.minima)[-self.envelope:]
        a = float(min(di - skew * (ti - ref) for ti, di in recent))  # lowered onto the lowest recent minimum
        if self.fitted:  # falls by at most max_step_us a window (at the latest sample); rises at once
            now = self.last_ap
            a += max(0.0, self.offset_at(now) - self.max_step_us - (a + skew * (now - ref)))
        self.ref, self.a, self.skew, self.fitted = ref, a, skew, True

    def _fit_skew(self) -> float:
        """Least-squares slope of the window minima, clamped to +-max_skew."""
        n = len(self.minima)
        mt = sum(t for t, _ in self.minima) / n
        md = sum(d for _, d in self.minima) / n
        stt = sum((t - mt) ** 2 for t, _ in self.minima)
        if stt <= 0:
            return 0.0
        b = sum((t - mt) * (d - md) for t, d in self.minima) / stt
        return max(-self.max_skew, min(self.max_skew, b))
