"""`tools/sitl speed-curve`: success against one setting, from campaigns flown at its values.

Each folder is a finished campaign flown with `--set KEY=V`; KEY is cost.max_speed by default
(ForestCost's speed limit; a campaign without one is the row "no limit"), or any other of
mppid's settings (`--key mppi.rollouts`: success against the rollout count). One row per
(value, scenario, backend):
successes out of runs with the Wilson 95 % interval, the mean speed among the trees
(score.json's forest_speed) and the peak speed of the successful flights, the closest
approach of any flight, state -> command p99 (median and worst flight) and deadline misses.
--png draws success against the limit, one line per scenario and backend, with the intervals.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from .campaign import wilson
from .results import load_campaign
from .sidebyside import _median

SPEED_KEY = "cost.max_speed"


def speed_limit(sets: list, key: str = SPEED_KEY) -> float | None:
    """The campaign's value of `key` (the last --set of it wins, as in mppid), None without one."""
    limit, prefix = None, key + "="
    for s in sets or []:
        if s.startswith(prefix):
            limit = float(s[len(prefix):])
    return limit if limit else None


def _values(runs: list, key: str, ok_only: bool = False) -> list[float]:
    return [float(r[key]) for r in runs if isinstance(r.get(key), (int, float)) and math.isfinite(r[key])
            and (r.get("success") or not ok_only)]


def _mean(v):
    return sum(v) / len(v) if v else None


def _row(limit, scenario: str, runs: list) -> dict:
    n, k = len(runs), sum(1 for r in runs if r.get("success"))
    s2c = _values(runs, "state_to_command_ms_p99")
    return {"limit": limit, "scenario": scenario, "backend": runs[0].get("backend", "?"), "runs": n, "successes": k,
            "wilson95": list(wilson(k, n)), "forest_speed": _mean(_values(runs, "forest_speed", ok_only=True)),
            "peak_speed": _mean(_values(runs, "peak_speed", ok_only=True)),
            "min_clearance": min(_values(runs, "min_clearance"), default=None),
            "state_to_command_p99_median": _median(s2c), "state_to_command_p99_worst": max(s2c, default=None),
            "deadline_misses": int(sum(_values(runs, "deadline_misses"))),
            "seeds": sorted(r.get("seed") for r in runs)}


def rows(folders: list[Path], key: str = SPEED_KEY) -> list[dict]:
    """One row per (value of key, scenario, backend) over the folders, by value (none last)."""
    groups: dict[tuple, list] = {}
    for folder in folders:
        c = load_campaign(folder)
        limit = speed_limit(c.summary.get("sets"), key)
        for scen, runs in c.by_scenario().items():
            for r in runs:
                groups.setdefault((limit, scen, r.get("backend", "?")), []).append(r)
    order = sorted(groups, key=lambda g: (g[0] is None, g[0] or 0.0, g[1], g[2]))
    return [_row(g[0], g[1], groups[g]) for g in order]


def _f(v, fmt="{:.2f}"):
    return "-" if v is None else fmt.format(v)


def markdown(table: list[dict], key: str = SPEED_KEY) -> str:
    head = "speed limit [m/s]" if key == SPEED_KEY else key
    lines = [f"| {head} | scenario | backend | success | 95 % CI (Wilson) | speed in the trees [m/s] | "
             "peak [m/s] | closest [m] | state->command p99 median / worst [ms] | misses |",
             "|---:|---|---|---:|---|---:|---:|---:|---|---:|"]
    for r in table:
        lo, hi = r["wilson95"]
        lines.append(f"| {_f(r['limit'], '{:g}') if r['limit'] else ('no limit' if key == SPEED_KEY else 'not set')} | {r['scenario']} | {r['backend']} | "
                     f"{r['successes']}/{r['runs']} | {100 * lo:.0f}-{100 * hi:.0f} % | {_f(r['forest_speed'])} | "
                     f"{_f(r['peak_speed'])} | {_f(r['min_clearance'])} | "
                     f"{_f(r['state_to_command_p99_median'], '{:.1f}')} / {_f(r['state_to_command_p99_worst'], '{:.1f}')} | "
                     f"{r['deadline_misses']} |")
    return "\n".join(lines) + "\n"


def plot(table: list[dict], png: Path, key: str = SPEED_KEY) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    lines: dict[tuple, list] = {}
    for r in table:
        if r["limit"] is not None:
            lines.setdefault((r["scenario"], r["backend"]), []).append(r)
    for i, ((scen, backend), rs) in enumerate(sorted(lines.items())):
        x = [r["limit"] + 0.08 * (i - (len(lines) - 1) / 2) for r in rs]  # side by side, not on top
        y = [r["successes"] / r["runs"] for r in rs]
        err = [[p - r["wilson95"][0] for p, r in zip(y, rs)], [r["wilson95"][1] - p for p, r in zip(y, rs)]]
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=f"{scen} ({backend})")
    if key == SPEED_KEY:
        ax.hlines(0.8, 7.0, max((r["limit"] for r in table if r["limit"]), default=10.0), colors="grey",
                  linestyles="dashed", label="AERO-MPPI: > 80 % above 7 m/s (LiDAR; arXiv 2509.17340)")
    else:
        ax.set_xscale("log", base=2)
    ax.set_xlabel("speed limit [m/s]" if key == SPEED_KEY else key)
    ax.set_ylabel("success rate (95 % Wilson interval)")
    ax.set_ylim(0, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main(folders: list[Path], png: Path | None = None, json_out: Path | None = None, key: str = SPEED_KEY) -> str:
    table = rows(folders, key)
    if png:
        plot(table, png, key)
    if json_out:
        json_out.write_text(json.dumps(table, indent=2))
    return markdown(table, key)
