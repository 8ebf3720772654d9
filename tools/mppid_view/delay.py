"""The live view's delay (docs/view.md, "Delay"): from a state's publish on the bus to the end
of the flush that hands its drawing to the viewer's server, on the host's wall clock."""
from __future__ import annotations

import statistics
from collections import deque

WALL_STAMP_S = 5.0   # a utime this close to the receipt is on the wall clock (real time)


def bus_wall_time(state, ticks: dict[int, int], received: float) -> float:
    """When a vehicle_state_t was published, in seconds on the host's wall clock. Real time:
    its utime (the simulator's and the bridges' publish stamp). Lock-step (utime is simulated
    time): the wall utime of the simulator's tick for the same sample (published right after
    the state). Otherwise (no tick yet): its receipt by the view."""
    if abs(state.utime * 1e-6 - received) < WALL_STAMP_S:
        return state.utime * 1e-6
    tick = ticks.get(state.sample_utime)
    return tick * 1e-6 if tick is not None else received


class DelayStats:
    """The delays of the draws so far, in seconds (the newest million)."""

    def __init__(self, keep: int = 1_000_000):
        self.delays: deque = deque(maxlen=keep)

    def add(self, seconds: float) -> None:
        self.delays.append(seconds)

    def summary(self) -> dict:
        d = sorted(self.delays)
        if not d:
            return {"draws": 0}
        return {"draws": len(d), "median_s": statistics.median(d), "p95_s": d[min(len(d) - 1, int(0.95 * len(d)))],
                "max_s": d[-1]}

    def line(self) -> str:
        """One line for the log (the view test reads it): the summary as key=value."""
        s = self.summary()
        if not s["draws"]:
            return "view: delay bus -> viewer's server: no state drawn yet"
        return (f"view: delay bus -> viewer's server: draws={s['draws']} median_ms={1e3 * s['median_s']:.1f} "
                f"p95_ms={1e3 * s['p95_s']:.1f} max_ms={1e3 * s['max_s']:.1f}")
