"""The controller's timing over a flight: one definition, used by score.json and timing.png.

Definitions (all in ms):

  compute_ms_p99    99th percentile over the flight's cycles of the time from a cycle's
                    start to its command leaving (command_t.compute_us): every cycle counts
                    once, wherever it falls. Null when the log has no per-cycle times.
  compute_ms_p50, compute_ms_max, compute_ms_mean
                    the median, the longest and the mean of the same per-cycle times.
  state_age_ms_p99  the state's age at the start of the cycles that optimised from it
                    (command_t.age_us; 0 in lock-step, where the cycle starts on the tick).
  state_to_command_ms_p99, state_to_command_ms_p50
                    age + compute of the fresh commands: the state's sample time to the
                    command leaving, the controller's real latency (in real time; in
                    lock-step the age is 0 and the simulator measures it, per tick).
                    Its per-cycle values are `state_to_command_samples_ms` (timing.png's
                    first panel in real time).
  lead_ms_mean, lead_ms_p99
                    the span each state was predicted over (command_t.lead_us: sample time
                    -> the command's expected actuation), with latency compensation on.
  period_ms_p99, jitter_ms_p99
                    from the status windows (pooled: the largest window p99, see below).
  compute_ms_p99_worst_window, period_ms_p99_worst_window, jitter_ms_p99_worst_window
                    the largest per-window p99 that any controller_status_t reported. A
                    window is the cycles since the previous status (1 s at the shipped
                    1 Hz), and the daemon also closes a window early on a mode change, so a
                    window of three cycles that holds one slow cycle reports that cycle as
                    its "p99": this is a worst case, not the flight's p99, and is named so.

Per-cycle times come from the commands: each command the loop sends carries its cycle's
age, compute and lead (command_t age_us, compute_us, lead_us). Commands of the deadline
guard (sent while the optimizer overran) carry none and are not cycles of their own.
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
    out = {k: None for k in ("compute_ms_p99", "compute_ms_p50", "compute_ms_max", "compute_ms_mean", "period_ms_p99", "jitter_ms_p99",
                             "compute_ms_p99_worst_window", "period_ms_p99_worst_window",
                             "jitter_ms_p99_worst_window")}
    out.update(compute_samples_ms=None, timing_cycles=0, timing_source=None)
    windows = _status_windows(list(status_msgs))
    if not windows:
        return out
    total = sum(n for n, _ in windows)
    _window_figures(out, windows, total)
    single = [m for n, m in windows if n == 1]
    if total > 0 and len(single) >= PER_CYCLE_MIN_COVERAGE * total:
        _per_cycle_figures(out, single)
    return out


def _status_windows(msgs) -> list:
    """(cycles in the window, message) for each message that covers cycles.

    Each message covers the cycles since the previous one (counter `cycles` runs since
    start). Messages that close an empty window (the final status, say) or step the counter
    back (a restarted daemon) hold no cycles."""
    windows = []
    prev = 0
    for m in msgs:
        n = int(m.cycles) - prev
        if n > 0:
            windows.append((n, m))
        prev = max(prev, int(m.cycles))
    return windows


def _window_figures(out: dict, windows, total: int) -> None:
    """The worst window's p99s and maximum, the cycle-weighted mean compute time."""
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


def _per_cycle_figures(out: dict, single) -> None:
    """Percentiles over one-cycle windows (a status per cycle): each holds its cycle's values."""
    comp = np.array([m.compute_ms_last for m in single], float)
    comp = comp[np.isfinite(comp)]
    # The first cycle has no period; a one-cycle window's p99 is that cycle's value.
    per = np.array([m.period_ms_p99 for m in single[1:]], float)
    jit = np.array([m.jitter_ms_p99 for m in single[1:]], float)
    per, jit = per[np.isfinite(per)], jit[np.isfinite(jit)]
    if comp.size:
        out["compute_ms_p99"] = float(np.percentile(comp, 99))
        out["compute_ms_p50"] = float(np.percentile(comp, 50))
        out["compute_samples_ms"] = comp.tolist()
        out["timing_source"] = "per-cycle status"
    if per.size:
        out["period_ms_p99"] = float(np.percentile(per, 99))
    if jit.size:
        out["jitter_ms_p99"] = float(np.percentile(jit, 99))


def command_timing(command_msgs) -> dict:
    """Per-cycle figures from the commands (see the module docstring); empty when the
    commands carry no timing (an older log, or the stand-in controller)."""
    fresh = [m for m in command_msgs if int(getattr(m, "compute_us", 0)) > 0]
    if not fresh:
        return {}
    comp = np.array([m.compute_us for m in fresh], float) / 1e3
    normal = [m for m in fresh if int(m.mode) == 0]
    out = {"compute_ms_p99": float(np.percentile(comp, 99)), "compute_ms_p50": float(np.percentile(comp, 50)),
           "compute_ms_max": float(comp.max()),
           "compute_ms_mean": float(comp.mean()), "compute_samples_ms": comp.tolist(),
           "timing_cycles": len(fresh), "timing_source": "per-cycle commands"}
    if normal:
        age = np.array([m.age_us for m in normal], float) / 1e3
        out["state_age_ms_p99"] = float(np.percentile(age, 99))
        state_to_command = age + np.array([m.compute_us for m in normal], float) / 1e3
        out["state_to_command_ms_p99"] = float(np.percentile(state_to_command, 99))
        out["state_to_command_ms_p50"] = float(np.percentile(state_to_command, 50))
        out["state_to_command_samples_ms"] = state_to_command.tolist()
        lead = np.array([m.lead_us for m in normal if m.lead_us > 0], float) / 1e3
        if lead.size:
            out["lead_ms_mean"] = float(lead.mean())
            out["lead_ms_p99"] = float(np.percentile(lead, 99))
    return out


def flight_timing(status_msgs, command_msgs=()) -> dict:
    """The flight's figures: per-cycle ones from the commands where they exist, the rest
    (periods, worst windows) from the status stream."""
    out = status_timing(status_msgs)
    out.update(state_age_ms_p99=None, state_to_command_ms_p99=None, state_to_command_ms_p50=None,
               state_to_command_samples_ms=None, lead_ms_mean=None, lead_ms_p99=None)
    out.update(command_timing(command_msgs))
    return out
