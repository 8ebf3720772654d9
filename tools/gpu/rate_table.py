#!/usr/bin/env python3
"""The loop-rate table (issue 24) from the campaigns of tools/gpu/cycle-compare.sh's `flights`:
FOLDER/<backend>-<rate>/<group>/summary.json, one campaign per task group.

    tools/gpu/rate_table.py FOLDER     # markdown on stdout
"""
import json
import statistics
import sys
from pathlib import Path


def runs(folder: Path) -> list[dict]:
    out = []
    for s in folder.glob("*/summary.json"):
        out += json.loads(s.read_text())["runs"]
    return out


def cell_success(rs: list[dict], scenario: str) -> str:
    mine = [r for r in rs if r.get("scenario") == scenario]
    return f"{sum(bool(r.get('success')) for r in mine)}/{len(mine)}" if mine else "-"


def main() -> int:
    root = Path(sys.argv[1])
    print("| backend | loop Hz | rate_track_circle_fast RMSE m (success) | forest_4m | forest_4m_robust | team3_fixed "
          "| state->command p50 / p99 ms | deadline misses | flights |")
    print("|---|---:|---|---|---|---|---|---:|---:|")
    rows = []
    for d in root.iterdir():
        if d.is_dir() and "-" in d.name:
            backend, rate = d.name.rsplit("-", 1)
            rows.append((backend, float(rate), d))
    for backend, rate, d in sorted(rows, key=lambda r: (r[0] != "cuda", r[1])):
        rs = runs(d)
        track = [r for r in rs if r.get("scenario") == "rate_track_circle_fast"]
        rmse = [r["tracking_rmse"] for r in track if r.get("tracking_rmse") is not None]
        rmse_txt = f"{statistics.mean(rmse):.3f} ({cell_success(rs, 'rate_track_circle_fast')})" if rmse else "-"
        p50 = [r["state_to_command_ms_p50"] for r in rs if r.get("state_to_command_ms_p50") is not None]
        p99 = [r["state_to_command_ms_p99"] for r in rs if r.get("state_to_command_ms_p99") is not None]
        lat = f"{statistics.median(p50):.2f} / {max(p99):.2f}" if p50 and p99 else "-"
        misses = sum(int(r.get("deadline_misses") or 0) for r in rs)
        print(f"| {backend} | {rate:g} | {rmse_txt} | {cell_success(rs, 'forest_4m')} | {cell_success(rs, 'forest_4m_robust')} "
              f"| {cell_success(rs, 'team3_fixed')} | {lat} | {misses} | {len(rs)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
