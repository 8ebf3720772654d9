"""mppid-realsense: an Intel RealSense D4xx's depth frames as point_cloud_t for mppid-mapper
(docs/sensing.md, "A RealSense camera").

  mppid-realsense [--config FILE] [--set key=value ...] [--bag FILE] [--lcm-url URL]
                  [--sensor-lcm-url URL] [--stats FILE]
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

from . import settings as settings_mod

NAME = "mppid-realsense"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog=NAME, description="An Intel RealSense D4xx's depth frames as point_cloud_t (MPPI_DEPTH) for "
        "mppid-mapper, placed by the vehicle's state (vehicle_state_t) and the camera's mounting.")
    p.add_argument("--config", help="settings file (YAML; config/realsense/realsense.yaml); without it the defaults")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting, e.g. range.max=8 or mount.rotation_deg=[0,15,0] (repeatable)")
    p.add_argument("--bag", metavar="FILE",
                   help="play a recording (.bag, .db3) instead of a camera, not in real time, then exit")
    p.add_argument("--lcm-url", help="the states' bus (overrides lcm_url)")
    p.add_argument("--sensor-lcm-url", help="the frames' bus (overrides sensor_lcm_url; default: the states' bus)")
    p.add_argument("--stats", metavar="FILE", help="on exit: frames, refusals by reason, points (JSON)")
    return p.parse_args(argv)


def event(name: str, **fields) -> None:
    print(json.dumps({"event": name, **fields}), flush=True)


def run(a: argparse.Namespace, s) -> int:
    import lcm
    import mppi_lcm

    from .camera import Camera
    from .driver import Driver

    url = a.lcm_url if a.lcm_url is not None else s.lcm_url
    sensor_url = a.sensor_lcm_url if a.sensor_lcm_url is not None else (s.sensor_lcm_url or url)
    states_bus = lcm.LCM(url) if url else lcm.LCM()
    frames_bus = states_bus if sensor_url == url else lcm.LCM(sensor_url)
    drv = Driver(s, mppi_lcm, frames_bus.publish)
    states_bus.subscribe(s.state_channel, lambda ch, data: drv.on_state_bytes(data))
    camera = Camera(s, a.bag)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    event("ready", channel=s.channel, state=s.state_channel)
    try:
        # No frame can be placed before the first state: the camera starts with it.
        while not stop.is_set() and not drv.states.first.is_set():
            states_bus.handle_timeout(100)
        if not stop.is_set():
            camera.start(drv.on_frame_safe)
            event("streaming", source=a.bag or "camera", width=camera.profile.width(),
                  height=camera.profile.height(), fps=camera.profile.fps())
        while not stop.is_set() and not camera.ended.is_set():
            states_bus.handle_timeout(100)
    finally:
        camera.stop()
        if a.stats:
            drv.write_stats(a.stats)
    st = drv.stats()
    event("done", frames=st["frames"], published=st["published"], rejected=st["rejected"])
    return 0


def main(argv=None) -> int:
    a = parse_args(argv)
    try:
        s = settings_mod.load(a.config, a.set)
    except settings_mod.SettingsError as e:
        print(f"{NAME}: {e}", file=sys.stderr)
        return 2
    try:
        return run(a, s)
    except RuntimeError as e:
        print(f"{NAME}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
