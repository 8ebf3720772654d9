#!/usr/bin/env python3
"""The paper's Fig. 11 on our hardware: time per MPPI iteration against rollouts (log axes)
for one, three and nine quadrotors (quadrotor_forest, team3_forest, team9_forest), with the
20 ms real-time line.

  bench/figures/fig11.py assemble BENCH.jsonl --gpu NAME --date DATE [--note TEXT] -o RESULT.json
      gather mppid-bench's JSON lines (one per configuration) into one result file
  bench/figures/fig11.py plot RESULT.json [-o FIG.png]
      draw it (default: the JSON's name with .png)
"""
import argparse
import json
import os
import sys

TASKS = [("quadrotor_forest", "1 quadrotor (16 states)"),
         ("team3_forest", "3 quadrotors (48 states)"),
         ("team9_forest", "9 quadrotors (144 states)")]
REAL_TIME_MS = 20.0


def assemble(args):
    rows = []
    with open(args.bench) as f:
        for line in f:
            line = line.strip()
            if line.startswith("{"):
                rows.append(json.loads(line))
    if not rows:
        sys.exit(f"fig11: no JSON lines in {args.bench}")
    out = {
        "figure": "Fig. 11: time per MPPI iteration against rollouts",
        "gpu": args.gpu,
        "date": args.date,
        "command": args.command,
        "settings": "config/tasks/<task>.yaml of the commit (horizon 100, dt 0.02; quadrotor sigma 60), "
                    "obstacles: the nearest 32 of the offline scenario's forest",
        "note": args.note,
        "results": rows,
    }
    with open(args.output, "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")
    print(f"wrote {args.output} ({len(rows)} configurations)")


def plot(args):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(args.result) as f:
        data = json.load(f)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
    for (task, label), marker in zip(TASKS, "osD"):
        pts = sorted((r["rollouts"], r["median_us"] / 1000.0, r["p99_us"] / 1000.0)
                     for r in data["results"] if r["task"] == task)
        if not pts:
            continue
        k = [p[0] for p in pts]
        ax.plot(k, [p[1] for p in pts], marker=marker, label=label + " (median)")
        ax.fill_between(k, [p[1] for p in pts], [p[2] for p in pts], alpha=0.2)
    ax.axhline(REAL_TIME_MS, color="k", linestyle="--", linewidth=1)
    ax.text(ax.get_xlim()[0] * 1.1 if ax.get_xlim()[0] > 0 else 300, REAL_TIME_MS * 1.12,
            "real time (20 ms, 50 Hz)", fontsize=8)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("rollouts K (horizon T = 100)")
    ax.set_ylabel("time per iteration [ms] (band: median to p99)")
    ax.set_title(f"MPPI iteration time, CUDA backend on {data['gpu']}\n({data['date']})", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out = args.output or os.path.splitext(args.result)[0] + ".png"
    fig.savefig(out)
    print(f"wrote {out}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("assemble")
    a.add_argument("bench")
    a.add_argument("--gpu", required=True)
    a.add_argument("--date", required=True)
    a.add_argument("--command", default="")
    a.add_argument("--note", default="")
    a.add_argument("-o", "--output", required=True)
    p = sub.add_parser("plot")
    p.add_argument("result")
    p.add_argument("-o", "--output")
    args = ap.parse_args()
    assemble(args) if args.cmd == "assemble" else plot(args)


if __name__ == "__main__":
    main()
