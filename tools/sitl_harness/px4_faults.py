"""The failsafe flights through PX4 SITL (`tools/sitl run --autopilot px4 --fault ACTION@T`):
what fails, and the two helpers that make it fail inside the flight's namespace.

Faults, T seconds after the mission's first path leg starts (mission.jsonl):
    kill_mppid      mppid SIGKILLed (the harness, flights/px4.py)
    stop_bridge     the bridge SIGSTOPped for good: PX4's offboard stream and the companion's
                    HEARTBEAT stop together (the harness)
    gcs_hold        a ground station switches PX4 to Hold (DO_SET_MODE, PX4's GCS link)
    gcs_position    ... to Position
    link_cut:D      the link between PX4 and the bridge cut for D seconds: the bridge reaches
                    PX4 through `relay` below, which drops every datagram both ways meanwhile

    python -m sitl_harness.px4_faults mode MAIN [SUB]         (one DO_SET_MODE, then exit)
    python -m sitl_harness.px4_faults relay --listen 14540 --to 14541 --out DIR
        (SIGUSR1: cut for --cut-s seconds; each cut and restore a line in DIR/relay.jsonl)
"""
from __future__ import annotations

import argparse
import json
import os
import select
import signal
import socket
import sys
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

PX4_GCS_PORT = 18570       # PX4's GCS link listens here (px4-rc.mavlink: -u 18570 -o 14550)
BRIDGE_PORT = 14541        # with link_cut, the bridge's own port behind the relay
FAULTS = ("kill_mppid", "stop_bridge", "gcs_hold", "gcs_position", "link_cut")
GCS_MODES = {"gcs_hold": (4, 3), "gcs_position": (3, 0)}   # PX4 (main, sub)


def parse_fault(text: str) -> tuple[str, float, float]:
    """ACTION@T or link_cut:D@T -> (action, T, D)."""
    try:
        what, at = text.rsplit("@", 1)
        action, _, dur = what.partition(":")
        t, d = float(at), float(dur or 0.0)
    except ValueError:
        raise ValueError(f"--fault {text!r}: expected ACTION@SECONDS (link_cut:SECONDS@SECONDS)") from None
    if action not in FAULTS:
        raise ValueError(f"--fault {text!r}: {action!r} is not one of {', '.join(FAULTS)}")
    if action == "link_cut" and d <= 0:
        raise ValueError(f"--fault {text!r}: link_cut needs a duration, link_cut:5@8 (say)")
    return action, t, d


def path_started(out: Path) -> bool:
    """Whether the mission tool has started its first leg that is not a hold (mission.jsonl)."""
    p = out / "mission.jsonl"
    if not p.is_file():
        return False
    for line in p.read_text().splitlines():
        try:
            r = json.loads(line)
        except ValueError:
            continue
        if r.get("event") == "step" and r.get("leg", -1) >= 0 and r.get("kind") != "hold":
            return True
    return False


def set_mode(main: int, sub: int) -> int:
    from pymavlink import mavutil
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{PX4_GCS_PORT}", source_system=255, source_component=190)
    ml = mavutil.mavlink
    for _ in range(10):
        conn.mav.heartbeat_send(ml.MAV_TYPE_GCS, ml.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        conn.mav.command_long_send(1, 1, ml.MAV_CMD_DO_SET_MODE, 0, ml.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub,
                                   0, 0, 0, 0)
        m = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.5)
        if m is not None and m.command == ml.MAV_CMD_DO_SET_MODE:
            print(json.dumps({"event": "mode_set", "main": main, "sub": sub, "result": m.result}), flush=True)
            return 0 if m.result == ml.MAV_RESULT_ACCEPTED else 1
    return 1


def relay(listen: int, to: int, out: Path, cut_s: float) -> int:
    """PX4 <-> relay <-> bridge, both ways, dropping everything while cut."""
    a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    a.bind(("127.0.0.1", listen))          # PX4 sends here, and hears back from here
    b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    b.bind(("127.0.0.1", 0))                # the bridge hears PX4 from here
    px4, cut_until = None, 0.0
    log = open(out / "relay.jsonl", "a", buffering=1)

    def cut(*_):
        nonlocal cut_until
        cut_until = time.monotonic() + cut_s
        log.write(json.dumps({"event": "cut", "wall_us": time.time_ns() // 1000, "for_s": cut_s}) + "\n")
    signal.signal(signal.SIGUSR1, cut)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    print(json.dumps({"event": "ready"}), flush=True)
    restored = True
    while True:
        ready, _, _ = select.select([a, b], [], [], 0.1)
        on = time.monotonic() >= cut_until
        if on and not restored:
            log.write(json.dumps({"event": "restored", "wall_us": time.time_ns() // 1000}) + "\n")
        restored = on
        for s in ready:
            data, src = s.recvfrom(65536)
            if s is a:
                px4 = src
                if on:
                    b.sendto(data, ("127.0.0.1", to))
            elif on and px4 is not None:
                a.sendto(data, px4)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="px4_faults", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("mode")
    m.add_argument("main", type=int)
    m.add_argument("sub", type=int, nargs="?", default=0)
    r = sub.add_parser("relay")
    r.add_argument("--listen", type=int, default=14540)
    r.add_argument("--to", type=int, default=BRIDGE_PORT)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--cut-s", type=float, default=5.0)
    a = ap.parse_args(argv)
    if a.cmd == "mode":
        return set_mode(a.main, a.sub)
    return relay(a.listen, a.to, a.out, a.cut_s)


if __name__ == "__main__":
    sys.exit(main())
