"""Parameter updates at set times of a flight (`tools/sitl run --param T:KEY=VALUE`).

Runs inside the flight's network namespace: follows the state stream (T is seconds of
sample time since the first state, so a lock-step flight gets its updates at the same
simulated times however fast it runs), publishes each update on MPPI_PARAMS when its time
comes, and prints one JSON line per update sent and per answer (MPPI_PARAM_RESULT), until
SIGTERM.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time


def parse_update(text: str) -> tuple[float, str, float]:
    """'2.5:mppi.rollouts=512' -> (2.5, 'mppi.rollouts', 512.0)."""
    try:
        when, rest = text.split(":", 1)
        key, value = rest.split("=", 1)
        return float(when), key.strip(), float(value)
    except ValueError:
        raise ValueError(f"--param {text!r}: expected SECONDS:KEY=VALUE, e.g. 2.5:mppi.rollouts=512") from None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="sitl_harness.inject")
    ap.add_argument("--lcm-url", required=True)
    ap.add_argument("--at", action="append", default=[], metavar="T:KEY=VALUE")
    a = ap.parse_args(argv)
    schedule = sorted((parse_update(s) for s in a.at), key=lambda u: u[0])

    import lcm
    from mppi_lcm import param_result_t, param_update_t, vehicle_state_t

    # A lock-step flight bursts thousands of datagrams a second: a large receive buffer, and
    # an error of one handle (a datagram lost to an overrun) is not the end of the flight.
    url = a.lcm_url + ("&" if "?" in a.lcm_url else "?") + "recv_buf_size=4194304"
    def connect():
        c = lcm.LCM(url)
        c.subscribe("MPPI_STATE", guarded(on_state))
        c.subscribe("MPPI_PARAM_RESULT", guarded(on_result))
        return c

    clock = {"first": None, "now": 0.0}

    def on_state(_ch, data):
        try:
            m = vehicle_state_t.decode(data)
        except ValueError:
            return
        if clock["first"] is None:
            clock["first"] = m.sample_utime
        clock["now"] = (m.sample_utime - clock["first"]) * 1e-6

    def on_result(_ch, data):
        try:
            r = param_result_t.decode(data)
        except ValueError:
            return
        print(json.dumps({"event": "result", "update_seq": r.update_seq, "key": r.key, "value": r.value,
                          "applied": r.status == param_result_t.STATUS_APPLIED, "cycle": r.cycle,
                          "reason": r.reason}), flush=True)

    def guarded(fn):
        def call(ch, data):
            try:
                fn(ch, data)
            except Exception as e:  # noqa: BLE001 - a callback must not end the handle loop
                import traceback
                traceback.print_exc()
        return call

    lc = connect()
    # Subscribed: the harness starts the simulator only now, so the first state seen is the
    # flight's first (T counts from it; a lock-step flight runs seconds ahead of a late start).
    print(json.dumps({"event": "ready"}), flush=True)
    running = {"on": True}
    signal.signal(signal.SIGTERM, lambda *_: running.update(on=False))
    seq = 0
    errors = 0
    while running["on"]:
        try:
            lc.handle_timeout(20)
        except OSError as e:
            if not running["on"]:
                break  # SIGTERM interrupted the wait
            errors += 1
            if errors <= 3:
                print(json.dumps({"event": "lcm_error", "error": str(e)}), flush=True)
            # The Python binding's udpm instance does not recover from a failed handle
            # (seen under lock-step bursts): a fresh one does.
            lc = connect()
        while schedule and clock["first"] is not None and clock["now"] >= schedule[0][0]:
            when, key, value = schedule.pop(0)
            seq += 1
            p = param_update_t()
            p.utime, p.seq, p.key, p.value = int(time.time() * 1e6), seq, key, value
            lc.publish("MPPI_PARAMS", p.encode())
            print(json.dumps({"event": "sent", "seq": seq, "key": key, "value": value, "at_s": when,
                              "state_time_s": clock["now"]}), flush=True)
    print(json.dumps({"event": "end", "state_time_s": clock["now"], "lcm_errors": errors,
                      "not_sent": [f"{t:g}:{k}={v:g}" for t, k, v in schedule]}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
