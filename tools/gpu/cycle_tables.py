#!/usr/bin/env python3
"""Markdown tables of a cycle comparison (tools/gpu/cycle-compare.sh) from its result files.

    cycle_tables.py bench RESULTS_DIR     # mppid-bench and mppid-gpu-timing, base and this tree
    cycle_tables.py daemon LABEL FILE     # one daemon-bench row
"""
import json
import re
import sys
from pathlib import Path


def timing_docs(path: Path):
    """The JSON documents of a file of mppid-gpu-timing outputs (each tagged with tree and round)."""
    if not path.exists():
        return []
    return [json.loads(d) for d in re.findall(r"\{\"tree\".*?\n\}\n", path.read_text(), re.S)]


def bench(res: Path) -> None:
    lines = (res / "bench.jsonl").read_text().splitlines() if (res / "bench.jsonl").exists() else []
    if lines:
        print("\n| tree | task | K | mppid-bench median us | p99 |\n|---|---|---:|---:|---:|")
    for line in lines:
        if line.startswith("{"):
            r = json.loads(line)
            print(f"| {r['tree']} | {r['task']} | {r['rollouts']} | {r['median_us']:.1f} | {r['p99_us']:.1f} |")
    print("\n| mppid-gpu-timing | tree/round | task | K | median us | p99 |\n|---|---|---|---:|---:|---:|")
    for f in sorted(res.glob("gpu-timing*.json")):
        for d in timing_docs(f):
            for r in d["results"]:
                print(f"| {f.stem} | {d['tree']}/{d['round']} | {r['task']} | {r['rollouts']} | {r['median_us']} | "
                      f"{r['p99_us']} |")


def daemon(label: str, path: Path) -> None:
    d = json.loads(path.read_text())["daemon"]
    f = lambda k: f"{d[k]['mean_ms']:.3f} / {d[k]['p99_ms']:.2f}"
    print(f"| {label} | {d['rate_hz']} | {d['rollouts']} | {d['cycles']} | {d['misses']} | {f('latency')} | {f('age')} | "
          f"{f('wake')} | {f('optimize')} | {f('compute')} |")


if __name__ == "__main__":
    if sys.argv[1] == "bench":
        bench(Path(sys.argv[2]))
    else:
        daemon(sys.argv[2], Path(sys.argv[3]))
