#!/usr/bin/env python3
"""Where a state's time goes, stage by stage, from the autopilot's message to the setpoint
the bridge sends (docs/latency.md), from a flight's bridge trace (`trace.file`; tools/sitl
--autopilot ardupilot writes bridge_trace.jsonl):

    .venv/bin/python drivers/mavlink/tools/stages.py FLIGHT_DIR [--json]

Per setpoint answering a state for the first time (monotonic clock, this host):
  autopilot -> bridge   the sample's arrival, later than the link's least (the autopilot's own
                        sending, e.g. ArduPilot SITL's serial flush at the end of its loop, TCP):
                        (arrival - autopilot stamp) less its minimum over the flight
  pair and convert      the attitude's arrival -> the state's LCM publish begins (ArduPilot: its
                        position follows in the same burst; NED -> ENU, checks)
  LCM publish           publish begins -> returns
  mppid wake + return   publish returned -> the command received, less mppid's compute: the
                        loop's wake-up on the state and the command's LCM trip back
  mppid compute         command_t.compute_us: the cycle's start -> its command published
  bridge forward        the command received -> SET_ATTITUDE_TARGET sent (gate, thrust map)
  bridge total          the state's arrival -> the setpoint sent
  sample -> command     mppid's own figure, command_t age + compute (the sample's time on this
                        host's clock, through clock_sync, to the command out)
Decoding happens inside pymavlink before the bridge sees a message; `decode` times it apart
(pymavlink's parser on a burst of ATTITUDE_QUATERNION + LOCAL_POSITION_NED, this machine).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")


def first_answers(trace: Path) -> list[dict]:
    seen, out = set(), []
    for line in trace.read_text().splitlines():
        r = json.loads(line)
        if not r.get("state_rx_mono_us") or r["state_seq"] in seen:
            continue
        seen.add(r["state_seq"])
        out.append(r)
    if len(out) < 20:
        sys.exit(f"stages: {trace}: {len(out)} setpoints with stage times (a bridge from 2026-11-26 on writes them)")
    return out


def decode_us(n: int = 2000) -> float:
    """pymavlink's parse of one ArduPilot state burst (two messages), us."""
    from pymavlink.dialects.v20 import ardupilotmega as mav
    enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    burst = (mav.MAVLink_attitude_quaternion_message(1000, 1, 0, 0, 0, 0.1, 0.2, 0.3, [0, 0, 0, 0]).pack(enc)
             + mav.MAVLink_local_position_ned_message(1000, 1, 2, -3, 0.1, 0.2, 0.3).pack(enc))
    dec = mav.MAVLink(None)
    t0 = time.perf_counter()
    for _ in range(n):
        msgs = dec.parse_buffer(burst)
        assert msgs and len(msgs) == 2
    return (time.perf_counter() - t0) / n * 1e6


def stages(rows: list[dict]) -> dict[str, np.ndarray]:
    a = {k: np.array([r[k] for r in rows], float) for k in (
        "state_rx_mono_us", "state_pub_mono_us", "state_pubdone_mono_us", "cmd_rx_mono_us", "mono_us",
        "age_us", "compute_us", "state_time_usec")}
    late = a["state_rx_mono_us"] - a["state_time_usec"]
    return {
        "autopilot -> bridge": late - late.min(),
        "pair and convert": a["state_pub_mono_us"] - a["state_rx_mono_us"],
        "LCM publish": a["state_pubdone_mono_us"] - a["state_pub_mono_us"],
        "mppid wake + return": a["cmd_rx_mono_us"] - a["state_pubdone_mono_us"] - a["compute_us"],
        "mppid compute": a["compute_us"],
        "bridge forward": a["mono_us"] - a["cmd_rx_mono_us"],
        "bridge total (arrival -> setpoint)": a["mono_us"] - a["state_rx_mono_us"],
        "sample -> command (mppid: age + compute)": a["age_us"] + a["compute_us"],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("flight", type=Path, help="a flight folder (bridge_trace.jsonl) or a trace file")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    trace = a.flight / "bridge_trace.jsonl" if a.flight.is_dir() else a.flight
    rows = first_answers(trace)
    out = {k: {"p50_ms": float(np.percentile(v, 50)) / 1e3, "p90_ms": float(np.percentile(v, 90)) / 1e3,
               "p99_ms": float(np.percentile(v, 99)) / 1e3, "max_ms": float(v.max()) / 1e3}
           for k, v in stages(rows).items()}
    dec = decode_us()
    if a.json:
        print(json.dumps({"trace": str(trace), "states": len(rows), "decode_us_per_burst": dec, "stages": out},
                         indent=2))
        return 0
    print(f"{trace}: {len(rows)} states answered; decode {dec:.0f} us a burst (inside pymavlink, apart)")
    print("| stage | p50 [ms] | p90 [ms] | p99 [ms] | max [ms] |\n|---|---:|---:|---:|---:|")
    for k, v in out.items():
        print(f"| {k} | {v['p50_ms']:.2f} | {v['p90_ms']:.2f} | {v['p99_ms']:.2f} | {v['max_ms']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
