"""The autopilot's clock on this machine's: when a MAVLink sample was taken, in our time.

An autopilot stamps its telemetry with its own clock (`time_boot_ms`, `time_usec` since
boot). mppid judges a state's age from its `sample_utime` on this machine's wall clock, so
the bridge maps one onto the other. The clocks do not keep together: a crystal drifts by
tens of ppm, and PX4's SIH in lock-step on a loaded 2-core machine ran 0.7 % to 5.8 % slow
and stood still for 0.22 s now and then (its lock-step loop starved). A mapping fixed once
(or relaxed by 100 us/s, the bridge's first one) makes every state look older by the
second, until mppid holds its plan for good.

The model: receive = a + (1 + skew) * autopilot + delay, delay >= 0 (transport and
scheduling), and steps in `a` when the autopilot's clock stands still or jumps.

- Windows: over each `window_s` of autopilot time the least-delayed sample (the minimum of
  receive - autopilot) is kept, the last `windows` of them (20 s).
- Skew: the median of the slopes between consecutive minima (a step bends one of them, not
  the median), clamped to +-`max_skew` (20 %: a fit that says more is wrong).
- Offset: the line through them is lowered onto the lowest of the last `envelope` minima (a
  lower envelope: no kept sample maps later than it arrived). Until two windows are closed,
  the line runs through the running minimum with the skew found before (none at first).
- A sample maps onto the line, never later than its own arrival.
- Steps (the autopilot's clock stood still, or the route changed): when every
  sample for `step_s` arrives more than `step_us` later (or earlier) than the line allows,
  the line moves by the least excess, onto the least-delayed sample since, and the envelope
  forgets the minima from before (the skew's median needs no help). A stalled receiver
  cannot fake a step up (its queued samples arrive together, the newest with little delay),
  but a queue on the sender's side lasting longer than `step_s` looks like one: its samples
  look fresher than they are (never later than they arrived) until it drains, and the step
  down then undoes it. The choice, made by a flight: after each of SIH's 0.2 s stalls mppid
  holds (its states look old) and the bridge pauses the stream until the step is taken,
  while PX4 flies the last rate setpoint on (up to COM_OF_LOSS_T, 1 s): 0.35 s of a 3 rad/s
  roll rate flipped the vehicle. So `step_s` is short (0.1 s), not the envelope's 2 s.
- Falls within `step_us`: a refit lowers the line by at most `max_step_us` a window.
- Start over: the autopilot's clock went back more than `reset_s` (a reboot), or a sample
  arrived `reset_s` before the line allows (its clock jumped ahead). The skew is kept.

Every time is in integer microseconds. `update` is O(1) except at a window's close (a
median over `windows` slopes, twice a second).
"""
from __future__ import annotations

import statistics
from collections import deque


class ClockSync:
    def __init__(self, window_s: float = 0.5, windows: int = 40, envelope: int = 4, max_skew: float = 0.2,
                 max_step_us: int = 5000, step_us: int = 10_000, step_s: float = 0.1, reset_s: float = 1.0):
        if (window_s <= 0 or windows < 2 or not 1 <= envelope <= windows or max_skew < 0 or max_step_us <= 0
                or step_us <= 0 or step_s <= 0 or reset_s <= 0):
            raise ValueError("clock_sync: window_s > 0, windows >= 2, 1 <= envelope <= windows, max_skew >= 0, "
                             "max_step_us, step_us, step_s, reset_s > 0")
        self.window_us = int(window_s * 1e6)
        self.envelope = int(envelope)
        self.max_skew = float(max_skew)
        self.max_step_us = int(max_step_us)
        self.step_us, self.step_window_us = int(step_us), int(step_s * 1e6)
        self.reset_us = int(reset_s * 1e6)
        self.minima: deque[list[int]] = deque(maxlen=windows)  # [autopilot us, receive - autopilot, sample no.]
        self.resets = self.steps = self.n = 0
        self.skew = 0.0
        self._start()

    def _start(self):
        """Forget the offset; the skew (the clocks' rates) is kept: a reboot does not change it."""
        self.minima.clear()
        self.bin_start = None         # autopilot time the open window began
        self.bin_min = None           # [autopilot us, receive - autopilot, sample no.], the least-delayed in it
        self.ref, self.a = 0, None    # the line: offset(t) = a + skew * (t - ref)
        self.fitted = False           # the line is a fit (else through the running minimum)
        self.off = None               # [autopilot us, sample no., side, least excess]: off the line since
        self.step_n = 0               # sample no. of the last step
        self.last_ap = None

    def offset_at(self, ap_us: int) -> float:
        """receive - autopilot for a sample taken at `ap_us` and sent with the least delay."""
        return self.a + self.skew * (ap_us - self.ref)

    def update(self, ap_us: int, recv_us: int) -> int:
        """One sample: the autopilot's stamp and when it arrived (this machine's clock, us).
        Returns when it was taken, on this machine's clock."""
        ap_us, recv_us = int(ap_us), int(recv_us)
        d = recv_us - ap_us
        self.n += 1
        if self.last_ap is not None and (ap_us < self.last_ap - self.reset_us
                                         or d < self.offset_at(ap_us) - self.reset_us):
            self.resets += 1          # rebooted, or its clock jumped ahead
            self._start()
        self.last_ap = ap_us
        if self.bin_start is None:
            self.bin_start = ap_us
        if self.bin_min is None or d - self.skew * (ap_us - self.bin_min[0]) < self.bin_min[1]:
            self.bin_min = [ap_us, d, self.n]  # the least delay, the drift within the window taken out
        if not self.fitted and (self.a is None or d < self.offset_at(ap_us)):
            self.ref, self.a = ap_us, float(d)
        self._watch_step(ap_us, d)
        if ap_us - self.bin_start >= self.window_us:
            self._close_window()
        return min(recv_us, int(round(ap_us + self.offset_at(ap_us))))

    def _watch_step(self, ap_us: int, d: int):
        """Every sample for step_s off the line by more than step_us, the same way: a step."""
        excess = d - self.offset_at(ap_us)
        side = (excess > self.step_us) - (excess < -self.step_us)
        if side == 0:
            self.off = None
            return
        if self.off is None or self.off[2] != side:
            self.off = [ap_us, self.n, side, excess]
            return
        self.off[3] = min(self.off[3], excess)
        if ap_us - self.off[0] < self.step_window_us:
            return
        self.steps += 1
        self.a += self.off[3]         # onto the least-delayed sample since
        self.step_n = self.off[1]     # the envelope forgets the minima from before
        if self.bin_min[2] < self.step_n:
            self.bin_min = [ap_us, d, self.n]
        self.off = None

    def _close_window(self):
        self.minima.append(self.bin_min)
        self.bin_start, self.bin_min = self.last_ap, None
        if len(self.minima) < 2:
            return
        skew = self._fit_skew()
        ref = self.minima[-1][0]
        recent = [m for m in list(self.minima)[-self.envelope:] if m[2] >= self.step_n]
        # lowered onto the lowest recent minimum (since the last step)
        a = float(min(di - skew * (ti - ref) for ti, di, _ in recent)) if recent else self.offset_at(ref)
        if self.fitted:  # falls by at most max_step_us a window (at the latest sample)
            now = self.last_ap
            a += max(0.0, self.offset_at(now) - self.max_step_us - (a + skew * (now - ref)))
        self.ref, self.a, self.skew, self.fitted = ref, a, skew, True

    def _fit_skew(self) -> float:
        """The median slope between consecutive window minima, clamped to +-max_skew: a step
        (a stall before the fit, one below step_us) bends one slope of the many, not the fit."""
        m = self.minima
        slopes = [(b[1] - a[1]) / (b[0] - a[0]) for a, b in zip(m, list(m)[1:]) if b[0] > a[0]]
        if not slopes:
            return self.skew
        return max(-self.max_skew, min(self.max_skew, statistics.median(slopes)))
