"""mppid-mission: give mppid something to do. Flies a mission file, or one leg built from
the command line, against mppid-sim or a real autopilot (through the MAVLink bridge) alike;
`--guided URL` flies the same mission with ArduCopter's own position controller instead.

    mppid-mission fly config/missions/circle.yaml [--seed 51] [--bridge SOCKET] [--out DIR]
    mppid-mission from-autopilot --bridge SOCKET [--speed 2] [--wait-armed]   the mission
                                  uploaded to the autopilot from a ground station (from_autopilot.py)
    mppid-mission hold [X,Y,Z]                 mppid-mission goal X,Y,Z [--radius 1]
    mppid-mission circle --center X,Y,Z --radius 5 --speed 3 [--laps 2] [--ramp S]
    mppid-mission figure-eight --center X,Y,Z --radius 5 --speed 3 [--laps 1]
    mppid-mission waypoints X,Y,Z X,Y,Z ... [--speed 2]
    mppid-mission check [--seconds S] [--hover-thrust N]   propellers off: mppid's answer to the
                                                           attitude, beside it (check.py)
    common: [--lcm-url URL] [--bridge SOCKET] [--takeoff M] [--obstacles FILE.yaml]
            [--frame start|local] [--guided MAVLINK_URL] [--quiet]

Positions are in the mission's frame: `start` (default) takes x, y from where the vehicle is
when the mission starts and z above home; `local` is the autopilot's (or simulator's) frame.
Exit status: 0 the mission was done, 1 it failed or stopped, 2 a bad mission or argument.
"""
from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

import yaml

from . import plan as plan_mod

LCM_URL = "udpm://239.255.76.67:7667?ttl=0"


def _point(text: str) -> list[float]:
    try:
        p = [float(c) for c in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected X,Y,Z")
    if len(p) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected X,Y,Z")
    return p


def _parser():
    ap = argparse.ArgumentParser(prog="mppid-mission", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--lcm-url", default=LCM_URL)
    common.add_argument("--bridge", metavar="SOCKET", help="the bridge's control socket: arm, take off, hand over, land")
    common.add_argument("--guided", metavar="MAVLINK_URL", help="fly with ArduCopter's GUIDED position controller")
    common.add_argument("--seed", type=int, default=1, help="seeds the mission's virtual forest")
    common.add_argument("--out", type=Path, help="folder for mission.jsonl and mission_summary.json")
    common.add_argument("--quiet", action="store_true")
    legs = argparse.ArgumentParser(add_help=False)
    legs.add_argument("--takeoff", type=float, help="take off to this altitude first (autopilot)")
    legs.add_argument("--obstacles", type=Path, help="YAML: trees: [[x, y, r], ...] and/or forest: {...}")
    legs.add_argument("--frame", choices=("start", "local"), default="start")
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fly", parents=[common], help="fly a mission file")
    f.add_argument("mission", type=Path)
    fa = sub.add_parser("from-autopilot", parents=[common], help="fly the mission uploaded to the autopilot")
    fa.add_argument("--speed", type=float, default=2.0, help="m/s until a DO_CHANGE_SPEED (default 2)")
    fa.add_argument("--wait-armed", action="store_true",
                    help="wait for the vehicle to be armed from the ground station, then read and fly the mission")
    h = sub.add_parser("hold", parents=[common, legs], help="hold a point (default: where the vehicle is)")
    h.add_argument("at", nargs="?", type=_point)
    h.add_argument("--for", dest="seconds", type=float)
    g = sub.add_parser("goal", parents=[common, legs], help="fly to a goal (forest tasks: around the trees)")
    g.add_argument("at", type=_point)
    g.add_argument("--radius", type=float, default=1.0)
    g.add_argument("--timeout", type=float, default=60.0)
    w = sub.add_parser("waypoints", parents=[common, legs], help="lines through the points")
    w.add_argument("points", nargs="+", type=_point)
    for name in ("circle", "figure-eight"):
        c = sub.add_parser(name, parents=[common, legs], help=f"fly a {name}")
        c.add_argument("--center", type=_point, required=True)
        c.add_argument("--radius", type=float, required=True)
        c.add_argument("--laps", type=float, default=1.0)
    k = sub.add_parser("check", help="propellers off: what mppid would command against what the autopilot reports")
    k.add_argument("--lcm-url", default=LCM_URL)
    k.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: at Ctrl-C)")
    k.add_argument("--hover-thrust", type=float, metavar="N", help="the vehicle's mass x g, to show thrust against it")
    for p in (w, sub.choices["circle"], sub.choices["figure-eight"]):
        p.add_argument("--speed", type=float, required=p is not w, default=None if p is not w else 1.0)
        p.add_argument("--ramp", type=float, help="seconds to reach full speed (default speed / 1 m/s^2)")
    return ap


def _one_leg(a) -> dict:
    opt = {k: v for k, v in (("ramp", getattr(a, "ramp", None)),) if v is not None}
    if a.cmd == "hold":
        leg = {"hold": {**({"at": a.at} if a.at else {}), **({"for": a.seconds} if a.seconds else {})}}
    elif a.cmd == "goal":
        leg = {"goal": {"at": a.at, "radius": a.radius, "timeout": a.timeout}}
    elif a.cmd == "waypoints":
        leg = {"waypoints": {"points": a.points, "speed": a.speed, **opt}}
    else:
        leg = {a.cmd.replace("-", "_"): {"center": a.center, "radius": a.radius, "speed": a.speed, "laps": a.laps,
                                         **opt}}
    doc = {"name": a.cmd, "frame": a.frame, "legs": [leg]}
    if a.takeoff is not None:
        doc["takeoff"] = a.takeoff
    if a.obstacles:
        doc["obstacles"] = yaml.safe_load(a.obstacles.read_text()) or {}
    return doc


def main(argv=None) -> int:
    a = _parser().parse_args(argv)
    if a.cmd == "check":
        from .check import run
        return run(a.lcm_url, a.seconds, a.hover_thrust)
    if a.cmd == "from-autopilot":
        return _from_autopilot(a)
    try:
        mission = plan_mod.load(a.mission) if a.cmd == "fly" else plan_mod.from_dict(_one_leg(a), a.cmd)
    except (plan_mod.PlanError, OSError, yaml.YAMLError) as e:
        print(f"mppid-mission: {e}", file=sys.stderr)
        return 2
    say = _start_flying(a)
    from .runner import Runner
    from .vehicles import FlightError, GuidedLink, MppidLink
    try:
        channels = {"obstacles": mission.trees_channel} if mission.trees_channel else None
        link = GuidedLink(a.guided) if a.guided else MppidLink(a.lcm_url, a.bridge, channels)
    except (FlightError, OSError) as e:
        print(f"mppid-mission: {e}", file=sys.stderr)
        return 1
    try:
        summary = Runner(mission, link, seed=a.seed, out=a.out, say=say).run()
    finally:
        link.close()
    return 0 if summary["outcome"] == "done" else 1


def _start_flying(a):
    """The record's folder made, SIGTERM (systemd, the harness) taken as Ctrl-C (the vehicle
    is left holding, the record written); returns the progress printer (--quiet: none)."""
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    return (lambda s: None) if a.quiet else (lambda s: print(f"{time.strftime('%H:%M:%S')} {s}", flush=True))


def _from_autopilot(a) -> int:
    if not a.bridge or a.guided:
        print("mppid-mission from-autopilot: --bridge SOCKET (the bridge reads the mission), without --guided",
              file=sys.stderr)
        return 2
    if not 0.05 <= a.speed <= 30:
        print(f"mppid-mission from-autopilot: --speed {a.speed:g}: m/s in [0.05, 30]", file=sys.stderr)
        return 2
    say = _start_flying(a)
    from .from_autopilot import run
    from .vehicles import MppidLink
    link = MppidLink(a.lcm_url, a.bridge)
    try:
        return run(link, a.speed, a.seed, a.out, say, a.wait_armed)
    finally:
        link.close()


if __name__ == "__main__":
    sys.exit(main())
