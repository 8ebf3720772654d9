"""The controller's timing over a flight: one definition, used by score.json and timing.png.

Definitions (all in ms):

  compute_ms_p99    99th percentile of the optimizer's compute time over the flight's
                    cycles: every cycle counts once, wherever it falls. Needs per-cycle
                    compute times; null when the log has none (see below).
  compute_ms_max    the longest cycle of the flight (exact from any status stream: the
                    largest window maximum).
  compute_ms_mean   the mean over the flight's cycles (window means weighted by the cycles
                    each window holds).
  period_ms_p99, jitter_ms_p99
                    the same pooling for the time between cycle starts and |period - nominal|.
  compute_ms_p99_worst_window, period_ms_p99_worst_window, jitter_ms_p99_worst_window
                    the largest per-window p99 that any controller_status_t reported. A
                    window is the cycles since the previous status (1 s at the shipped
                    1 Hz), and the daemon also closes a window early on a mode change, so a
                    window of three cycles that holds one slow cycle reports that cycle as
                    its "p99": this is a worst case, not the flight's p99, and is named so.

Where per-cycle times come from: controller_status_t carries statistics of its window
only, so the harness asks the daemon for one status message per cycle
(`daemon.status_hz` = `daemon.rate_hz`, set in flight.py before the scenario's and the
user's --set, which may override it). A status message whose window holds exactly one
cycle (its cycle counter one above the previous message's) gives that cycle's time
exactly. The per-cycle figures are computed when such messages cover at least
PER_CYCLE_MIN_COVERAGE of the flight's cycles (the logger may miss a few datagrams);
otherwise they are null and only the worst-window figures are given.
"""
from __future__ import annotations

import math

import numpy as np

PER_CYCLE_MIN_COVERAGE = 0.9


def _finite(v) -> bool:
    return v is not None and isinstance(v, (int, float)) and math.isfinite(v)


def status_timing(status_msgs) -> dict:
    """Timing figures of a flight from its controller_status_t messages (in log order).

    Returns the keys of the module docstring plus `compute_samples_ms` (the per-cycle
    compute times, a list, or None), `timing_cycles` (cycles the figures cover),
    `timing_source` ("per-cycle status" or "status windows")."""
    out = {k: None for k in ("compute_ms_p99", "compute_ms_max", "compute_ms_mean", "period_ms_p99", "jitter_ms_p99",
                             "compute_ms_p99_worst_window", "period_ms_p99_worst_window",
                             "jitter_ms_p99_worst_window")}
    out.update(compute_samples_ms=None, timing_cycles=0, timing_source=None)
    msgs = list(status_msgs)
    if not msgs:
        return out
    # Windows: each message covers the cycles since the previous one (counter `cycles`
    # runs since start). Messages that close an empty window (the final status, say) or
    # step the counter back (a restarted daemon) hold no cycles.
    windows = []  # (cycles in the window, message)
    prev = 0
    for m in msgs:
        n = int(m.cycles) - prev
        if n > 0:
            windows.append((n, m))
        prev = max(prev, int(m.cycles))
    if not windows:
        return out
    total = sum(n for n, _ in windows)

    def worst(field):
        vals = [getattr(m, field) for _, m in windows if _finite(getattr(m, field))]
        return float(max(vals)) if vals else None

    out["compute_ms_p99_worst_window"] = worst("compute_ms_p99")
    out["period_ms_p99_worst_window"] = worst("period_ms_p99")
    out["jitter_ms_p99_worst_window"] = worst("jitter_ms_p99")
    out["compute_ms_max"] = worst("compute_ms_max")
    means = [(n, m.compute_ms_mean) for n, m in windows if _finite(m.compute_ms_mean)]
    if means:
        out["compute_ms_mean"] = float(sum(n * v for n, v in means) / sum(n for n, _ in means))
    out["timing_cycles"] = total
    out["timing_source"] = "status windows"

    single = [m for n, m in windows if n == 1]
    if total > 0 and len(single) >= PER_CYCLE_MIN_COVERAGE * total:
        comp = np.array([m.compute_ms_last for m in single], float)
        comp = comp[np.isfinite(comp)]
        # The first cycle has no period; a one-cycle window's p99 is that cycle's value.
        per = np.array([m.period_ms_p99 for m in single[1:]], float)
        jit = np.array([m.jitter_ms_p99 for m in single[1:]], float)
        per, jit = per[np.isfinite(per)], jit[np.isfinite(jit)]
        if comp.size:
            out["compute_ms_p99"] = float(np.percentile(comp, 99))
            out["compute_samples_ms"] = comp.tolist()
            out["timing_source"] = "per-cycle status"
        if per.size:
            out["period_ms_p99"] = float(np.percentile(per, 99))
        if jit.size:
            out["jitter_ms_p99"] = float(np.percentile(jit, 99))
    return out


def status_rate_sets(cfg_path, sets) -> list[str]:
    """The --set that makes the daemon publish one controller_status_t per cycle:
    daemon.status_hz equal to the daemon's rate (daemon.rate_hz from the settings file,
    then from `sets`, the --set pairs that follow; 50 Hz by default)."""
    import yaml

    rate = 50.0
    try:
        doc = yaml.safe_load(open(cfg_path)) or {}
        rate = float(((doc.get("daemon") or {}).get("rate_hz")) or rate)
    except (OSError, yaml.YAMLError, TypeError, ValueError, AttributeError):
        pass
    for kv in sets:
        k, _, v = kv.partition("=")
        if k.strip() == "daemon.rate_hz":
            try:
                rate = float(yaml.safe_load(v))
            except (yaml.YAMLError, TypeError, ValueError):
                pass
    return [f"daemon.status_hz={rate:g}"]
