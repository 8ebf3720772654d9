"""The table of bench/figures/before-after's flights: per scenario and tree, successes,
medians of time to goal, closest obstacle, tracking RMSE and compute p99, deadline misses.

    python3 bench/figures/before_after.py OUT
"""
import argparse
import glob
import json
import statistics


def median(rows, key):
    v = [r[key] for r in rows if r.get(key) is not None]
    return f"{statistics.median(v):.3f}" if v else "-"


def main(out: str):
    print("| scenario | tree | success | time to goal [s] | closest [m] | tracking RMSE [m] | compute p99 [ms] | misses |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    scenarios = sorted({p.split("/")[-3] for p in glob.glob(f"{out}/*/*/seed_*/score.json")})
    for sc in scenarios:
        for label in ("base", "new"):
            rows = [json.load(open(f)) for f in sorted(glob.glob(f"{out}/{label}/{sc}/seed_*/score.json"))]
            ok = sum(1 for r in rows if r.get("success"))
            misses = sum(r.get("deadline_misses") or 0 for r in rows)
            print(f"| {sc} | {label} | {ok}/{len(rows)} | {median(rows, 'time_to_goal')} | {median(rows, 'min_clearance')} "
                  f"| {median(rows, 'tracking_rmse')} | {median(rows, 'compute_ms_p99')} | {misses} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", metavar="OUT", help="bench/figures/before-after's output folder "
                        "(OUT/<tree label>/<scenario>/seed_<n>/score.json)")
    main(parser.parse_args().out)
