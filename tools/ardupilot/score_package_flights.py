"""Scores the flights of `tools/package-test.sh --ardupilot-bin ... --keep DIR` (ArduCopter SITL
flown from the installed package) as the harness scores its own ArduCopter flights
(sitl_harness.ap_score: the SITL's truth against the mission's reference), and prints a
markdown table beside the package test's own verdicts (results.json).

    python tools/ardupilot/score_package_flights.py DIR
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace

from sitl_harness import ap_score, paths


def score(folder: Path, name: str) -> dict:
    mission = name.removesuffix("_kill")
    spec = SimpleNamespace(scenario=str(paths.ROOT / "config" / "missions" / f"{mission}.yaml"), seed=0,
                           controller="mppid")
    return ap_score.score_flight(folder / name, spec, {})


def row(name: str, s: dict) -> str:
    """The README table's figures: the path legs' truth RMSE (the hold legs' for hover)."""
    kind = "tracking" if "tracking_rmse" in s else "hover"
    legs = [v for k, v in s.get("legs", {}).items() if k.endswith("_hold") == (kind == "hover")]
    est = (sum(v["rmse_estimate"] ** 2 for v in legs) / len(legs)) ** 0.5 if legs else float("nan")
    nan = float("nan")
    return (f"| {name} | {s.get('mission_outcome')} | {s.get('success')} | {s.get(kind + '_rmse', nan):.3f} | "
            f"{s.get(kind + '_max', nan):.3f} | {est:.3f} | {s.get('max_tilt_deg') or nan:.0f} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, metavar="DIR",
                        help="the folder given to tools/package-test.sh --keep (results.json and one folder per flight)")
    folder = parser.parse_args(argv).folder
    results = json.loads((folder / "results.json").read_text())
    print("| flight | mission | success | truth RMSE m | truth max m | estimate RMSE m | max tilt deg |")
    print("|---|---|---|---|---|---|---|")
    scores = {}
    for name in sorted(p.name for p in folder.iterdir() if (p / "truth.jsonl").is_file()):
        scores[name] = score(folder, name)
        print(row(name, scores[name]))
    (folder / "scores.json").write_text(json.dumps(scores, indent=1, default=str))
    kill = results.get("circle_3ms_kill")
    if kill:
        print(f"\nmppid killed mid-circle: {json.dumps({k: v for k, v in kill.items() if k != 'cpu_share'})}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
