"""mppid-mavlink-bridge: `run` the bridge, or send it a control request (`arm`, `takeoff`,
`offboard`, `land`, `disarm`, `hold`, `status`)."""
from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading

from . import settings as settings_mod

CONTROL_CMDS = ("arm", "disarm", "takeoff", "offboard", "land", "hold", "identify", "status")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="mppid-mavlink-bridge", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the bridge")
    r.add_argument("--config", help="settings YAML (config/bridge/*.yaml)")
    r.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    r.add_argument("--url", help="MAVLink connection string (overrides mavlink.url)")
    r.add_argument("--vehicle", help="vehicle file (config/vehicles/*.yaml; overrides vehicle.file): mppid's --vehicle")
    r.add_argument("--lcm-url", help="LCM URL (overrides lcm.url)")
    r.add_argument("--log-level", default="info")
    r.add_argument("--realtime", type=int, metavar="PRIO",
                   help="SCHED_FIFO PRIO for the latency path's threads once started (overrides realtime.priority)")
    for c in CONTROL_CMDS:
        p = sub.add_parser(c, help=f"ask a running bridge to {c}")
        p.add_argument("--socket", default=settings_mod.DEFAULTS["control"]["socket"])
        p.add_argument("--timeout", type=float, default=30.0)
        if c == "takeoff":
            p.add_argument("altitude", nargs="?", type=float)
        if c == "identify":
            p.add_argument("on", nargs="?", type=int, choices=(0, 1), default=1,
                           help="1 (default): start mppid's identification manoeuvre; 0: stop it")
    a = ap.parse_args(argv)
    if a.cmd != "run":
        return _control(a)
    return _run(a)


def _control(a) -> int:
    """A control request to a running bridge; its answer on stdout."""
    from .control import request
    line = a.cmd + (f" {a.altitude}" if getattr(a, "altitude", None) is not None else "")
    line += f" {a.on}" if a.cmd == "identify" else ""
    try:
        reply = request(a.socket, line, a.timeout)
    except OSError as e:
        print(f"mppid-mavlink-bridge {a.cmd}: cannot reach the bridge at {a.socket}: {e}", file=sys.stderr)
        return 2
    print(json.dumps(reply, indent=2) if a.cmd == "status" else reply["message"])
    return 0 if reply.get("ok") else 1


def _run(a) -> int:
    logging.basicConfig(level=a.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s.%(msecs)03d %(levelname)s %(message)s", datefmt="%H:%M:%S")
    sets = list(a.set)
    if a.url:
        sets.append(f"mavlink.url={a.url}")
    if a.vehicle:
        sets.append(f"vehicle.file={a.vehicle}")
    if a.realtime is not None:
        sets.append(f"realtime.priority={a.realtime}")
    try:
        s = settings_mod.load(a.config, sets)
    except (settings_mod.SettingsError, OSError) as e:
        print(f"mppid-mavlink-bridge: {e}", file=sys.stderr)
        return 2
    from .bridge import Bridge
    from .control import ControlServer
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())
    from .signing import SigningError
    try:
        bridge = Bridge(s, lcm_url=a.lcm_url)
    except SigningError as e:
        print(f"mppid-mavlink-bridge: {e}", file=sys.stderr)
        return 2
    ctl = ControlServer(s["control"]["socket"], bridge.execute)
    bridge.start()
    ctl.start()
    logging.getLogger("mppi_mavlink").info("bridge running: MAVLink %s, LCM %s, control %s", s["mavlink"]["url"],
                                           bridge.lcm_url, s["control"]["socket"])
    _notify("READY=1")
    while not done.wait(1.0):
        _notify("WATCHDOG=1")
    _notify("STOPPING=1")
    ctl.close()
    bridge.close()
    return 0


def _notify(state: str):
    """sd_notify without libsystemd: one datagram to $NOTIFY_SOCKET."""
    import os
    import socket
    path = os.environ.get("NOTIFY_SOCKET")
    if not path:
        return
    if path.startswith("@"):
        path = "\0" + path[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as s:
            s.sendto(state.encode(), path)
    except OSError:
        pass


if __name__ == "__main__":
    sys.exit(main())
