"""tools/replay LOG: finds the daemon's settings of a recorded flight and runs mppid-replay.

The settings are the daemon's command line as the SITL harness ran it (harness.json beside
the log: --config, then every --set in order, --backend); --config/--set given here replace
them (a log recorded without the harness). Exit status: mppid-replay's (0 every command
identical, 1 a divergence, printed, 2 a usage or settings error).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def find_binary(name: str) -> Path | None:
    dirs = [os.environ.get("MPPID_BUILD_DIR"), "build", "build-sim"]
    for d in dirs:
        if not d:
            continue
        p = (ROOT / d / "bin" / name) if not os.path.isabs(d) else Path(d) / "bin" / name
        if p.is_file():
            return p
    return None


def daemon_args(cmd: list[str]) -> list[str]:
    """--config, --set (in order) and --backend of an mppid command line."""
    out = []
    it = iter(range(len(cmd)))
    for i in it:
        if cmd[i] in ("--config", "--set", "--backend") and i + 1 < len(cmd):
            out += [cmd[i], cmd[i + 1]]
            next(it, None)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/replay", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", type=Path, help="flight.lcmlog (a lock-step flight)")
    ap.add_argument("--config", help="the daemon's settings file (default: from harness.json)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="the daemon's overrides")
    ap.add_argument("--max-cycles", type=int, default=None)
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args(argv)
    binary = find_binary("mppid-replay")
    if binary is None:
        print("replay: mppid-replay not built (cmake --build build --target mppid-replay)", file=sys.stderr)
        return 2
    if a.config:
        args = ["--config", a.config] + [x for s in a.set for x in ("--set", s)]
    else:
        h = a.log.resolve().parent / "harness.json"
        try:
            info = json.loads(h.read_text())
            ctrl = info["commands"]["controller"]
        except (OSError, KeyError, json.JSONDecodeError) as e:
            print(f"replay: no daemon command line in {h} ({e!r}): give --config and --set", file=sys.stderr)
            return 2
        if "--lockstep" not in ctrl:
            print("replay: the flight ran in real time; the replay reproduces lock-step flights "
                  "(drivers/daemon/README.md says what a real-time replay would need)", file=sys.stderr)
            return 2
        args = daemon_args(ctrl) + [x for s in a.set for x in ("--set", s)]
    if a.max_cycles is not None:
        args += ["--max-cycles", str(a.max_cycles)]
    if a.verbose:
        args.append("--verbose")
    cmd = [str(binary), str(a.log)] + args
    print("replay: " + " ".join(cmd), file=sys.stderr, flush=True)
    os.execv(cmd[0], cmd)


if __name__ == "__main__":
    sys.exit(main())
