#!/usr/bin/env python3
"""Per-flight race-car figures from SITL result folders (truth.jsonl + score.json).

    .venv/bin/python bench/figures/racecar_flights.py results/rc/racecar_ellipse/seed_*

mean speed: the harness's (|(vx, vy)| over the flight); mean vx: the body's forward speed
alone (the paper's model moves the car sideways by vy, which its tires do not see); max |d|:
the track residual d = (x/13)^2 + (y/6)^2 - 1 (the scenario ends the flight at 0.6); slip:
the ground slip atan2(vy, vx), rad.
"""
import argparse
import json

import numpy as np


def main(folders):
    print("| flight | success | laps | mean speed [m/s] | mean vx [m/s] | max \\|d\\| | max slip [rad] | compute p99 [ms] | deadline misses |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for f in folders:
        s = json.load(open(f"{f}/score.json"))
        X = np.array([json.loads(line)["x"] for line in open(f"{f}/truth.jsonl") if '"x"' in line], float)
        d = (X[:, 0] / 13.0) ** 2 + (X[:, 1] / 6.0) ** 2 - 1.0
        slip = np.abs(np.arctan2(X[:, 5], X[:, 4]))
        name = "/".join(f.rstrip("/").split("/")[-2:])
        print(f"| {name} | {s['success']} | {s.get('laps', 0):.2f} | {s['mean_speed']:.3f} | {X[:, 4].mean():.2f} | "
              f"{np.abs(d).max():.3f} | {slip.max():.2f} | {s.get('compute_ms_p99')} | {s.get('deadline_misses')} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", metavar="FOLDER",
                        help="a SITL result folder holding truth.jsonl and score.json")
    main(parser.parse_args().folders)
