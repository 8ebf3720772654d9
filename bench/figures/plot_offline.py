#!/usr/bin/env python3
"""Plot an mppid-offline result folder: top view of the path over the obstacles, altitude,
speed and commands. Writes path.png into the folder."""
import argparse
import csv
import json
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in rows[0].keys()} if rows else {}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("folder")
    args = ap.parse_args()
    tr = read_csv(os.path.join(args.folder, "trajectory.csv"))
    score = json.load(open(os.path.join(args.folder, "score.json")))
    obs_path = os.path.join(args.folder, "obstacles.csv")
    obs = read_csv(obs_path) if os.path.exists(obs_path) else {}
    nx = sum(1 for k in tr if k.startswith("x"))
    nu = sum(1 for k in tr if k.startswith("u"))
    vehicles = max(1, nx // 16) if score["task"].startswith("team") else 1
    per = nx // vehicles
    fig, axes = plt.subplots(1, 3, figsize=(17, 5), gridspec_kw={"width_ratios": [2.2, 1, 1]})
    ax = axes[0]
    for x, y, r in zip(obs.get("x", []), obs.get("y", []), obs.get("radius", [])):
        ax.add_patch(plt.Circle((x, y), r, color="forestgreen", alpha=0.7))
    for j in range(vehicles):
        ax.plot(tr[f"x{j * per}"], tr[f"x{j * per + 1}"], lw=1.5, label=f"vehicle {j}" if vehicles > 1 else "path")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    outcome = "success" if score["success"] else "failure"
    ax.set_title(f"{score['task']} ({score['scenario']}), seed {score['seed']}: {outcome}")
    ax.legend(loc="upper left")
    ax.grid(alpha=0.3)
    t = tr["t"]
    if per >= 3 and score["task"].startswith(("quad", "team")):
        for j in range(vehicles):
            axes[1].plot(t, tr[f"x{j * per + 2}"])
        axes[1].set_ylabel("altitude [m]")
    else:
        axes[1].plot(t, tr["x0"])
        axes[1].set_ylabel("x0")
    axes[1].set_xlabel("t [s]")
    axes[1].grid(alpha=0.3)
    for i in range(min(nu, 8)):
        axes[2].plot(t, tr[f"u{i}"], lw=0.8)
    axes[2].set_xlabel("t [s]")
    axes[2].set_ylabel("commands")
    axes[2].grid(alpha=0.3)
    fig.tight_layout()
    out = os.path.join(args.folder, "path.png")
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
