"""A stand-in controller: answers every state with the hover (or zero) command. Used to
exercise the simulator and the harness without the daemon (`--controller standin`)."""
from __future__ import annotations

import argparse
import math
import select
import signal
import sys
import time

import yaml

from . import paths

HOVER_RPM = math.sqrt(0.25 * 9.81 / (4 * 6.11e-8))  # core's Quadrotor defaults


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenario", required=True)
    ap.add_argument("--lcm-url", default="")
    ap.add_argument("--die-after", type=float, default=0.0, help="exit after this many seconds (tests)")
    a = ap.parse_args(argv)
    import lcm
    from mppi_lcm import command_t, controller_status_t, vehicle_state_t

    sc = yaml.safe_load(open(paths.scenario_path(a.scenario)))
    model = sc["plant"]["model"]
    m = int(sc["plant"].get("vehicles", 1))
    if model == "quadrotor":
        u, kind = [HOVER_RPM] * 4 * m, command_t.KIND_MOTOR_SPEEDS
    elif model in ("quadrotor_rate", "quadrotor_rate_body"):
        mass = float((sc["plant"].get("params") or {}).get("mass", 1.0))
        u, kind = [mass * 9.81, 0.0, 0.0, 0.0] * m, command_t.KIND_THRUST_RATES
    elif model == "cartpole":
        u, kind = [0.0], command_t.KIND_GENERIC
    else:
        u, kind = [0.0, 0.0], command_t.KIND_GENERIC

    lc = lcm.LCM(a.lcm_url) if a.lcm_url else lcm.LCM()
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    seq = [0]

    def on_state(_chan, data):
        s = vehicle_state_t.decode(data)
        c = command_t()
        c.utime = s.utime
        c.seq = seq[0]
        c.state_seq = s.seq
        c.mode = command_t.MODE_NORMAL
        c.kind = kind
        c.n = len(u)
        c.u = u
        seq[0] += 1
        lc.publish("MPPI_COMMAND", c.encode())
        if seq[0] % 50 == 0:
            st = controller_status_t()
            st.utime, st.seq, st.backend, st.task = s.utime, seq[0] // 50, "standin", sc["task"]
            st.cycles, st.healthy = seq[0], 1
            lc.publish("MPPI_STATUS", st.encode())

    lc.subscribe("MPPI_STATE", on_state)
    t0 = time.monotonic()
    try:
        while not stop:
            if a.die_after and time.monotonic() - t0 > a.die_after:
                return 1
            r, _, _ = select.select([lc.fileno()], [], [], 0.1)
            if r:
                lc.handle()
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
