"""`tools/sitl table`: campaigns side by side, one row per scenario, as the README shows them.

Each folder is a finished campaign (summary.json). Typically two: the same scenarios and
seeds flown in real time and in lock-step with the controller's measured latency charged,
so a reader sees both outcomes, the figure of merit (time to goal, tracking RMSE or mean
speed), the compute p99 (the median over flights of each flight's p99 of per-cycle
compute, command_t.compute_us; the worst flight's in brackets), the deadline misses summed
over flights, and the smallest clearance of any flight.
"""
from __future__ import annotations

import re
from pathlib import Path

from .results import CampaignResults, load_campaign


def _label(results: CampaignResults) -> str:
    s = results.summary
    runs = results.runs
    backend = runs[0].get("backend", "?") if runs else "?"
    return f"{s.get('clock', '?')}, {backend}"


def _merit(runs: list) -> str:
    def mean(key):
        v = [r[key] for r in runs if r.get(key) is not None and r.get("success")]
        return sum(v) / len(v) if v else None
    t, rmse, speed = mean("time_to_goal"), mean("tracking_rmse"), mean("mean_speed")
    if t is not None:
        return f"goal in {t:.2f} s"
    if rmse is not None and speed is not None:
        return f"RMSE {rmse:.3f} m at {speed:.2f} m/s"
    if rmse is not None:
        return f"RMSE {rmse:.3f} m"
    if speed is not None:
        return f"{speed:.2f} m/s"
    return "-"


def _kind(reason: str) -> str:
    """A failure's kind: its reason without the time and vehicle ("collision with ground")."""
    return re.sub(r"\s*\(vehicle \d+\)|\s*at t=[\d.]+ s|\s*[\d.]+ m > [\d.]+", "", reason).strip()


def _median(v: list) -> float | None:
    v = sorted(x for x in v if x is not None)
    if not v:
        return None
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def rows(folder: Path) -> dict:
    """Per scenario: success, runs, merit, compute p99 median/worst, misses, clearance."""
    results = load_campaign(folder)
    out = {}
    for scen, runs in results.by_scenario().items():
        p99 = [r.get("compute_ms_p99") for r in runs]
        clear = [r.get("min_clearance") for r in runs if r.get("min_clearance") is not None]
        sep = [r.get("min_separation") for r in runs if r.get("min_separation") is not None]
        out[scen] = {
            "runs": len(runs),
            "success": sum(1 for r in runs if r.get("success")),
            "merit": _merit(runs),
            "compute_p99_median": _median(p99),
            "compute_p99_worst": max((x for x in p99 if x is not None), default=None),
            "misses": sum(int(r.get("deadline_misses") or 0) for r in runs),
            "min_clearance": min(clear) if clear else None,
            "min_separation": min(sep) if sep else None,
            "failures": _count_kinds([r.get("reason") or "?" for r in runs if not r.get("success")]),
        }
    return {"label": _label(results), "seeds": results.summary.get("seeds", []), "rows": out}


def _count_kinds(reasons: list) -> list:
    counts: dict = {}
    for r in reasons:
        counts[_kind(r)] = counts.get(_kind(r), 0) + 1
    return [f"{k} x{n}" if n > 1 else k for k, n in sorted(counts.items())]


def _fmt(x, spec="{:.2f}"):
    return "-" if x is None else spec.format(x)


def table(folders: list, names: list | None = None) -> str:
    """One column group per name; folders given the same name are merged (e.g. two real-time
    campaigns over different scenarios)."""
    names = names or [f"{i + 1}" for i in range(len(folders))]
    merged: dict = {}
    for n, f in zip(names, folders):
        d = rows(Path(f))
        if n in merged:
            merged[n]["rows"].update(d["rows"])
            merged[n]["seeds"] = sorted(set(merged[n]["seeds"]) | set(d["seeds"]))
            if d["label"] not in merged[n]["label"]:
                merged[n]["label"] += "; " + d["label"]
        else:
            merged[n] = d
    names = list(merged)
    data = [merged[n] for n in names]
    scen = []
    for d in data:
        for s in d["rows"]:
            if s not in scen:
                scen.append(s)
    head = ["scenario"]
    for n, d in zip(names, data):
        head += [f"{n}: success", f"{n}: result", f"{n}: compute p99 [ms] (worst)", f"{n}: misses",
                 f"{n}: min clearance [m]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in scen:
        cells = [s]
        for d in data:
            r = d["rows"].get(s)
            if r is None:
                cells += ["-"] * 5
                continue
            fail = f" ({', '.join(r['failures'])})" if r["failures"] else ""
            clear = r["min_clearance"] if r["min_clearance"] is not None else r["min_separation"]
            cells += [f"{r['success']}/{r['runs']}{fail}", r["merit"],
                      f"{_fmt(r['compute_p99_median'])} ({_fmt(r['compute_p99_worst'])})", str(r["misses"]),
                      _fmt(clear)]
        lines.append("| " + " | ".join(cells) + " |")
    legend = "; ".join(f"{n} = {d['label']}, seeds {_seed_span(d['seeds'])}" for n, d in zip(names, data))
    return "\n".join(lines) + f"\n\n{legend}\n"


def _seed_span(seeds: list) -> str:
    if not seeds:
        return "?"
    s = sorted(seeds)
    return f"{s[0]}-{s[-1]}" if s == list(range(s[0], s[-1] + 1)) else ",".join(map(str, s))
