"""tools/view: mppid in rerun's 3D viewer (docs/view.md).

  tools/view live [--lcm-url URL] [--sensor-lcm-url URL] [--web-port 9090] [--grpc-port 9876]
                  [--save FILE.rrd] [--seconds S]
      the live view of the LCM channels; prints the URL to open in a browser
  tools/view convert FLIGHT.lcmlog [OUT.rrd]
      a flight log (tools/record, tools/sitl's flight.lcmlog) as a rerun recording with the layout
  tools/view open FILE.rrd [--web-port 9090] [--grpc-port 9876]
      serves a recording in the web viewer (or: .venv/bin/rerun FILE.rrd, the native viewer)
  tools/view blueprint OUT.rbl
      the layout alone, for a recording made elsewhere
  tools/view screenshot URL OUT.png [--wait S]
      headless chromium's picture of a page (the live view's URL)
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="tools/view", description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    lv = sub.add_parser("live")
    lv.add_argument("--lcm-url", default=os.environ.get("LCM_DEFAULT_URL", "udpm://239.255.76.67:7667?ttl=0"))
    lv.add_argument("--web-port", type=int, default=9090)
    lv.add_argument("--grpc-port", type=int, default=9876)
    lv.add_argument("--save", help="also write the recording to this .rrd")
    lv.add_argument("--seconds", type=float, help="stop after this long (default: at SIGINT/SIGTERM)")
    lv.add_argument("--sensor-lcm-url", help="the sensors' frames (point_cloud_t) on this bus too")
    lv.add_argument("--netns-pid", type=int, default=0,
                    help="read LCM inside the network namespace of this process (a harness flight's), "
                         "serving the viewer in this one")
    cv = sub.add_parser("convert")
    cv.add_argument("log")
    cv.add_argument("out", nargs="?")
    op = sub.add_parser("open")
    op.add_argument("rrd")
    op.add_argument("--web-port", type=int, default=9090)
    op.add_argument("--grpc-port", type=int, default=9876)
    bp = sub.add_parser("blueprint")
    bp.add_argument("out")
    sh = sub.add_parser("screenshot")
    sh.add_argument("url")
    sh.add_argument("out")
    sh.add_argument("--wait", type=float, default=20.0)
    return ap


def cmd_live(a) -> int:
    from .live import LiveView
    view = LiveView(a.lcm_url, a.grpc_port, a.web_port, a.save, a.netns_pid, a.sensor_lcm_url)
    print(f"view: {view.url}", flush=True)
    counts = view.run(a.seconds)
    print(view.delay.line(), flush=True)
    print("view: drawn " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())), flush=True)
    return 0


def cmd_convert(a) -> int:
    from .convert import convert
    out = Path(a.out) if a.out else Path(a.log).with_suffix(".rrd")
    counts = convert(Path(a.log), out)
    print(f"{out}: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0 if counts else 1


def cmd_open(a) -> int:
    # rerun's own CLI (in the wheel) serves a file: its gRPC server and web viewer.
    from .live import viewer_url
    rerun = Path(sys.executable).with_name("rerun")
    print(f"view: {viewer_url(a.web_port, a.grpc_port)}  (Ctrl-C to stop)", flush=True)
    os.execv(str(rerun), [str(rerun), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(a.web_port),
                          "--port", str(a.grpc_port), a.rrd])
    return 2  # not reached


def cmd_blueprint(a) -> int:
    from .blueprint import blueprint
    blueprint().save("mppid", a.out)
    print(a.out)
    return 0


def cmd_screenshot(a) -> int:
    from .browser import HeadlessChromium
    with HeadlessChromium() as b:
        b.open(a.url)
        time.sleep(a.wait)  # the viewer draws for this long before the picture (not a timing check)
        Path(a.out).write_bytes(b.screenshot())
    print(a.out)
    return 0


COMMANDS = {"live": cmd_live, "convert": cmd_convert, "open": cmd_open, "blueprint": cmd_blueprint,
            "screenshot": cmd_screenshot}


def main(argv=None) -> int:
    os.environ.setdefault("RERUN_ANALYTICS", "0")  # offline; and nothing to send anyway
    a = parser().parse_args(argv)
    return COMMANDS[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())
