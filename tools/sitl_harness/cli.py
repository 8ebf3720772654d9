"""tools/sitl: list scenarios, run one, run a campaign, re-plot a result folder."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="sitl", description="mppid software-in-the-loop flights")
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="scenario names, one a line")

    r = sub.add_parser("run", help="fly one scenario; writes a result folder; exit 0 on success, 1 on failure")
    r.add_argument("--scenario", required=True, help="a name from `sitl list` or a YAML file")
    r.add_argument("--seed", type=int, default=1)
    r.add_argument("--backend", choices=["cpu", "cuda", "auto"], default="cpu")
    r.add_argument("--out", type=Path, default=None, help="result folder (default results/<scenario>-s<seed>-<time>)")
    r.add_argument("--realtime", action="store_true", help="real-time clock instead of lock-step")
    r.add_argument("--controller", choices=["mppid", "standin"], default="mppid",
                   help="standin: a hover stand-in (tests the simulator without the daemon)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="passed to mppid --set")
    r.add_argument("--timeout", type=float, default=0.0, help="wall-clock limit [s] (default from the scenario)")
    r.add_argument("--kill-controller-after", type=float, default=0.0, help=argparse.SUPPRESS)
    r.add_argument("--quiet", action="store_true")

    c = sub.add_parser("campaign", help="N seeds x scenarios, summary table with Wilson intervals")
    c.add_argument("--scenarios", required=True, help="comma-separated names")
    c.add_argument("--seeds", type=int, default=10)
    c.add_argument("--first-seed", type=int, default=1)
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--jobs", type=int, default=2, help="flights in parallel (lock-step only)")
    c.add_argument("--realtime-jobs", type=int, default=1, metavar="N",
                   help="with --realtime: N flights at once, each pinned (taskset) to its own 1/N of the CPUs "
                        "(default 1: one at a time)")
    c.add_argument("--backend", choices=["cpu", "cuda", "auto"], default="cpu")
    c.add_argument("--controller", choices=["mppid", "standin"], default="mppid")
    c.add_argument("--realtime", action="store_true")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="passed to mppid --set")

    p = sub.add_parser("plot", help="re-make the plots of a result folder")
    p.add_argument("folder", type=Path)

    a = ap.parse_args(argv)
    if a.cmd == "list":
        print("\n".join(paths.scenario_names()))
        return 0
    if a.cmd == "run":
        from .flight import FlightSpec, fly
        out = a.out or paths.ROOT / "results" / f"{Path(a.scenario).stem}-s{a.seed}-{time.strftime('%Y%m%d-%H%M%S')}"
        spec = FlightSpec(scenario=a.scenario, seed=a.seed, out=out, backend=a.backend, realtime=a.realtime,
                          controller=a.controller, wall_timeout=a.timeout, sets=a.set,
                          kill_controller_after=a.kill_controller_after)
        try:
            paths.scenario_path(a.scenario)
        except FileNotFoundError as e:
            print(f"sitl: {e}", file=sys.stderr)
            return 2
        try:
            score = fly(spec)
        except KeyboardInterrupt:
            print("sitl: interrupted; flight stopped and cleaned up", file=sys.stderr)
            return 130
        if not a.quiet:
            keys = ["success", "reason", "time_to_goal", "min_clearance", "tracking_rmse", "mean_speed",
                    "deadline_misses", "compute_ms_p99", "wall_s"]
            print(json.dumps({k: score.get(k) for k in keys}))
            print(f"results: {out}")
        return 0 if score.get("success") else 1
    if a.cmd == "campaign":
        from .campaign import run_campaign
        names = [s for s in a.scenarios.split(",") if s]
        for n in names:
            try:
                paths.scenario_path(n)
            except FileNotFoundError as e:
                print(f"sitl: {e}", file=sys.stderr)
                return 2
        try:
            summary = run_campaign(names, a.seeds, a.out, jobs=a.jobs, backend=a.backend, first_seed=a.first_seed,
                                   controller=a.controller, realtime=a.realtime, sets=a.set,
                                   realtime_jobs=a.realtime_jobs)
        except KeyboardInterrupt:
            print("\nsitl: campaign interrupted", file=sys.stderr)
            return 130
        print((Path(a.out) / "summary.md").read_text())
        return 0
    if a.cmd == "plot":
        from .plots import plot_flight
        for f in plot_flight(a.folder):
            print(f)
        return 0
    return 2
