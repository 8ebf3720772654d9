#!/usr/bin/env python3
"""The loop rate as a dial: what mppid and a scenario need to fly a task at RATE Hz.

    tools/gpu/rate_dial.py sets TASK RATE [--rollouts K] [--backend cuda|cpu]  # mppid --set pairs, one a line
    tools/gpu/rate_dial.py scenario SCENARIO RATE OUT.yaml                      # the scenario, states at RATE

One plan step per cycle (the daemon's convention: mppi.dt is the loop's period) and the same
horizon in seconds, so a faster loop has a longer plan: T = horizon_s * RATE. The task's tuning
(made at 50 Hz) carries over as the same continuous-time problem: with m = 50 Hz steps per new
step fewer (dt' = dt / m), the running cost sums m times as many terms, so lambda' = m lambda
keeps the weights' temperature, and the per-step noise sigma' = sqrt(m) sigma keeps the noise
integrated over a second (R = scale lambda / sigma^2 is then unchanged). The anytime margin is
kept below a quarter of the period. The scenario publishes states at RATE (the state trigger
starts a cycle per state) with physics at 2000 Hz (a whole multiple of 50 to 400 Hz).
"""
import argparse
import math
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def task_settings(task: str, backend: str) -> dict:
    doc = yaml.safe_load((ROOT / "config" / "tasks" / f"{task}.yaml").read_text())
    mppi = dict(doc.get("mppi") or {})
    daemon = dict(doc.get("daemon") or {})
    if backend == "cuda" and doc.get("cuda"):
        mppi.update(doc["cuda"].get("mppi") or {})
        daemon.update(doc["cuda"].get("daemon") or {})
    return {"mppi": mppi, "daemon": daemon}


def sets(task: str, rate: float, rollouts: int | None, backend: str) -> list[str]:
    s = task_settings(task, backend)
    m = s["mppi"]
    dt0, horizon0 = float(m.get("dt", 0.02)), int(m["horizon"])
    dt = 1.0 / rate
    scale = dt0 / dt  # m: new steps per 50 Hz step
    out = [
        f"daemon.rate_hz={rate:g}",
        f"mppi.dt={dt:.6g}",
        f"mppi.horizon={round(horizon0 * dt0 / dt)}",
        f"mppi.lambda={float(m['lambda']) * scale:.6g}",
        "mppi.sigma=[" + ",".join(f"{float(v) * math.sqrt(scale):.6g}" for v in m["sigma"]) + "]",
    ]
    margin = float(s["daemon"].get("anytime_margin_ms", 3.0))
    if margin > 250.0 / rate:
        out.append(f"daemon.anytime_margin_ms={250.0 / rate:.4g}")
    if rollouts:
        out.append(f"mppi.rollouts={rollouts}")
    return out


def scenario(name: str, rate: float, out: Path) -> None:
    path = Path(name) if name.endswith(".yaml") else ROOT / "config" / "scenarios" / f"{name}.yaml"
    doc = yaml.safe_load(path.read_text())
    timing = dict(doc.get("timing") or {})
    timing["state_hz"] = rate
    timing["physics_hz"] = 2000
    doc["timing"] = timing
    out.write_text(yaml.safe_dump(doc, sort_keys=False))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    a = sub.add_parser("sets")
    a.add_argument("task")
    a.add_argument("rate", type=float)
    a.add_argument("--rollouts", type=int, default=None)
    a.add_argument("--backend", choices=["cuda", "cpu"], default="cuda")
    b = sub.add_parser("scenario")
    b.add_argument("scenario")
    b.add_argument("rate", type=float)
    b.add_argument("out", type=Path)
    args = ap.parse_args()
    if args.what == "sets":
        print("\n".join(sets(args.task, args.rate, args.rollouts, args.backend)))
    else:
        scenario(args.scenario, args.rate, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
