"""Controllers side by side: campaigns of the same scenarios and seeds flown by different
controllers (e.g. `--controller mppid` and `--controller ddp`), one markdown table.

Per scenario and controller:
  success          flights that met the scenario's bar, of the flights
  time to goal     mean over its own successful flights; and over the seeds that every
                   controller completed (the same forests: a like-for-like figure)
  compute p50/p99  per cycle (command_t.compute_us): the median over flights of each
                   flight's p50 and of its p99; and the worst flight's p99
  clearance        the smallest obstacle clearance of any successful flight, and the median
                   over successful flights of each flight's minimum
  failures         the reasons of the failed flights, counted
"""
from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from statistics import mean, median

from .results import load_campaign


def _num(v):
    return v if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def load_runs(folder: Path) -> list[dict]:
    return load_campaign(folder).runs


def _fmt(v, digits=2):
    return "-" if v is None else f"{v:.{digits}f}"


def versus_rows(campaigns: list[tuple[str, list[dict]]]) -> list[dict]:
    """One row per (scenario, controller), scenarios in the first campaign's order."""
    scenarios = []
    for _, runs in campaigns:
        for r in runs:
            if r.get("scenario") not in scenarios:
                scenarios.append(r.get("scenario"))
    rows = []
    for scen in scenarios:
        by = {label: [r for r in runs if r.get("scenario") == scen] for label, runs in campaigns}
        common = None
        for label, rs in by.items():
            ok = {r["seed"] for r in rs if r.get("success")}
            common = ok if common is None else common & ok
        for label, rs in by.items():
            wins = [r for r in rs if r.get("success")]
            ttg = [_num(r.get("time_to_goal")) for r in wins]
            ttg = [t for t in ttg if t is not None]
            ttg_common = [_num(r.get("time_to_goal")) for r in wins if r["seed"] in (common or set())]
            ttg_common = [t for t in ttg_common if t is not None]
            p50 = [v for v in (_num(r.get("compute_ms_p50")) for r in rs) if v is not None]
            p99 = [v for v in (_num(r.get("compute_ms_p99")) for r in rs) if v is not None]
            clr = [v for v in (_num(r.get("min_clearance")) for r in wins) if v is not None]
            fails = Counter(str(r.get("reason")) for r in rs if not r.get("success"))
            rows.append({
                "scenario": scen, "controller": label, "runs": len(rs), "success": len(wins),
                "seeds": sorted(r["seed"] for r in rs),
                "time_to_goal": mean(ttg) if ttg else None,
                "time_to_goal_common": mean(ttg_common) if ttg_common else None, "common": len(common or ()),
                "compute_p50": median(p50) if p50 else None, "compute_p99": median(p99) if p99 else None,
                "compute_p99_worst": max(p99) if p99 else None,
                "clearance_min": min(clr) if clr else None, "clearance_median": median(clr) if clr else None,
                "failures": dict(fails),
            })
    return rows


def versus_markdown(rows: list[dict]) -> str:
    out = ["| scenario | controller | success | time to goal [s] (own successes / seeds both completed) "
           "| compute per cycle p50 / p99 [ms] (worst flight p99) | clearance min / median [m] | failures |",
           "|---|---|---:|---|---|---|---|"]
    for r in rows:
        fails = "; ".join(f"{k} x{v}" for k, v in r["failures"].items()) or "-"
        out.append(f"| {r['scenario']} | {r['controller']} | {r['success']}/{r['runs']} "
                   f"| {_fmt(r['time_to_goal'])} / {_fmt(r['time_to_goal_common'])} (n={r['common']}) "
                   f"| {_fmt(r['compute_p50'])} / {_fmt(r['compute_p99'])} ({_fmt(r['compute_p99_worst'])}) "
                   f"| {_fmt(r['clearance_min'])} / {_fmt(r['clearance_median'])} | {fails} |")
    return "\n".join(out) + "\n"


def versus(folders: list[Path], labels: list[str]) -> tuple[str, list[dict]]:
    if len(labels) != len(folders):
        raise ValueError(f"{len(folders)} folders but {len(labels)} labels")
    rows = versus_rows([(label, load_runs(f)) for label, f in zip(labels, folders)])
    return versus_markdown(rows), rows
