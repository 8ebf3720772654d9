"""mavlink-vehicle: the simulated autopilot (see ../README.md).

    python -m mavlink_vehicle --url udpout:127.0.0.1:14540 [--autopilot px4|ardupilot]
        [--world sim/mavlink_vehicle/worlds/circle.yaml] [--lcm-url URL] [--out DIR]
        [--param NAME=VALUE ...] [--duration S] [--signing-key-file FILE]

Writes DIR/truth.jsonl (state, applied command, mode at state_hz, and events), DIR/wire.jsonl
(what came in on the link, and when each ODOMETRY went out) and, on exit (SIGTERM/SIGINT or
--duration), DIR/vehicle_summary.json. With --signing-key-file (32 bytes, as 64 hex digits
or raw) the link is MAVLink 2 signed: everything sent is signed, only correctly signed
messages are taken, and the rest are counted (vehicle_summary.json: rejected_unsigned,
rejected_bad_signature).
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

from .vehicle import Vehicle, wall_us


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="mavlink-vehicle", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="udpout:127.0.0.1:14540")
    ap.add_argument("--autopilot", choices=("px4", "ardupilot"), default="px4")
    ap.add_argument("--world", help="world/mission YAML; publishes reference and obstacles on LCM")
    ap.add_argument("--lcm-url", default="udpm://239.255.76.67:7667?ttl=0")
    ap.add_argument("--out", help="folder for truth.jsonl, wire.jsonl, vehicle_summary.json")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--physics-hz", type=float, default=500.0)
    ap.add_argument("--state-hz", type=float, default=50.0)
    ap.add_argument("--mass", type=float, default=1.0)
    ap.add_argument("--start", default=None, help="x,y,z ENU (default: the world's start on the ground)")
    ap.add_argument("--duration", type=float, default=0.0)
    ap.add_argument("--clock-drift", type=float, default=0.0,
                    help="the autopilot's clock runs 1 + this as fast as the wall clock (stamps only; -0.007: "
                         "PX4 SIH lagging 0.7 %%); |drift| <= 0.05")
    ap.add_argument("--signing-key-file", help="MAVLink 2 signing key: 64 hex digits or 32 raw bytes")
    return ap


def checked(a) -> tuple[bytes | None, str | None]:
    """The signing key (None without one) and the first bad argument's message (None: all good)."""
    key = None
    if a.signing_key_file:
        raw = Path(a.signing_key_file).read_bytes()
        key = raw if len(raw) == 32 else bytes.fromhex(raw.decode().strip())
        if len(key) != 32:
            return key, "--signing-key-file must hold 32 bytes"
    if abs(a.clock_drift) > 0.05:
        return key, "--clock-drift must be within +-0.05"
    if a.physics_hz < 500:
        return key, "--physics-hz must be >= 500"
    return key, None


def load_world(a, out):
    """The world, its mission (publishing on LCM) and the start: (None, None, origin) without --world."""
    world = mission = None
    start = (0.0, 0.0, 0.0)
    if a.world:
        from mppi_mavlink import lcm_types
        import lcm
        from .world import Mission, load_world as load
        world = load(a.world)
        mission = Mission(world, lcm_types.import_mppi_lcm(), lcm.LCM(a.lcm_url), wall_us)
        start = (float(world["start"][0]), float(world["start"][1]), 0.0)
        if out:
            (Path(out) / "world.json").write_text(json.dumps(world, indent=1, default=list))
    if a.start:
        start = tuple(float(c) for c in a.start.split(","))
    return world, mission, start


def fly(v: Vehicle, a, out) -> None:
    """Runs the vehicle until --duration or SIGTERM/SIGINT; the summary on the way out."""
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    print(f"mavlink-vehicle: {a.autopilot} on {a.url}", flush=True)
    try:
        v.run(duration=a.duration, stop=stop)
    finally:
        v.events_flushed()
        v.close()
        if out:
            (Path(out) / "vehicle_summary.json").write_text(json.dumps(v.summary(), indent=1))


def main(argv=None) -> int:
    a = parser().parse_args(argv)
    key, error = checked(a)
    if error:
        print(f"mavlink-vehicle: {error}", file=sys.stderr)
        return 2
    params = {}
    for kv in a.param:
        k, v = kv.split("=", 1)
        params[k] = float(v)
    out = a.out
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
    world, mission, start = load_world(a, out)
    v = Vehicle(a.url, autopilot=a.autopilot, params=params, world=world, mission=mission, out=out,
                physics_hz=a.physics_hz, state_hz=a.state_hz, start=start, mass=a.mass, signing_key=key,
                clock_drift=a.clock_drift)
    fly(v, a, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
