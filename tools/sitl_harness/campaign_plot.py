"""Plots of a SITL campaign folder (summary.json from `tools/sitl campaign`): success rate
per scenario with its Wilson 95 % interval, and time to goal / min clearance per run
(summary.png).

    .venv/bin/python -m sitl_harness.campaign_plot RESULTS/campaign [--out FILE.png]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .results import load_campaign  # noqa: E402


def plot_campaign(folder: Path, out: Path | None = None) -> Path:
    data = load_campaign(folder)
    rows = data.summary["scenarios"]
    runs = data.runs
    names = list(rows)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    rate = np.array([rows[n]["success_rate"] for n in names])
    lo = np.array([rows[n]["wilson95"][0] for n in names])
    hi = np.array([rows[n]["wilson95"][1] for n in names])
    x = np.arange(len(names))
    axes[0].bar(x, 100 * rate, color="tab:green")
    # Clipped: a summary.json written before campaign.wilson() kept the rate inside its
    # interval may hold an end a rounding error beside it.
    yerr = np.clip([100 * (rate - lo), 100 * (hi - rate)], 0.0, None)
    axes[0].errorbar(x, 100 * rate, yerr=yerr, fmt="none", c="k", capsize=4)
    axes[0].set_ylabel("success [%] (Wilson 95 %)")
    for ax, key, label in ((axes[1], "time_to_goal", "time to goal [s]"), (axes[2], "min_clearance", "min clearance [m]")):
        for i, n in enumerate(names):
            vals = [r.get(key) for r in runs if r.get("scenario") == n and r.get(key) is not None]
            ok = [bool(r.get("success")) for r in runs if r.get("scenario") == n and r.get(key) is not None]
            jit = (np.random.default_rng(i).random(len(vals)) - 0.5) * 0.3
            ax.scatter(i + jit, vals, c=["tab:green" if o else "tab:red" for o in ok], s=14)
        ax.set_ylabel(label)
    for ax in axes:
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
    fig.tight_layout()
    out = out or Path(folder) / "summary.png"
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("folder", type=Path)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    print(plot_campaign(a.folder, a.out))


if __name__ == "__main__":
    main()
