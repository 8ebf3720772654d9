"""Parameter updates at set times of a flight (`tools/sitl run --param T:KEY=VALUE`).

Runs inside the flight's network namespace: follows the state stream (T is seconds of
sample time since the first state) and, once the first state is in, publishes every update on
MPPI_PARAMS with its apply_utime (the first state's sample time + T): mppid holds each until
the state of that time, so a lock-step flight applies its updates on the same cycles however
fast it runs, and a replay finds them there. Prints one JSON line per update sent and per
answer (MPPI_PARAM_RESULT), until SIGTERM.
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


def _guarded(fn):
    """A callback that cannot end the handle loop: its exception is printed."""
    def call(ch, data):
        try:
            fn(ch, data)
        except Exception:  # noqa: BLE001 - a callback must not end the handle loop
            import traceback
            traceback.print_exc()
    return call


def _emit(**event) -> None:
    print(json.dumps(event), flush=True)


class Injector:
    """Follows the state stream's sample time; publishes each update when its time comes."""

    def __init__(self, lcm_url: str, schedule: list):
        import lcm
        from mppi_lcm import param_result_t, param_update_t, vehicle_state_t

        self.lcm, self.types = lcm, (param_result_t, param_update_t, vehicle_state_t)
        # A lock-step flight bursts thousands of datagrams a second: a large receive buffer, and
        # an error of one handle (a datagram lost to an overrun) is not the end of the flight.
        self.url = lcm_url + ("&" if "?" in lcm_url else "?") + "recv_buf_size=4194304"
        self.schedule = schedule
        self.first, self.now, self.seq = None, 0.0, 0
        self.lc = self.connect()

    def connect(self):
        c = self.lcm.LCM(self.url)
        c.subscribe("MPPI_STATE", _guarded(self.on_state))
        c.subscribe("MPPI_PARAM_RESULT", _guarded(self.on_result))
        return c

    def on_state(self, _ch, data):
        try:
            m = self.types[2].decode(data)
        except ValueError:
            return
        if self.first is None:
            self.first = m.sample_utime
        self.now = (m.sample_utime - self.first) * 1e-6

    def on_result(self, _ch, data):
        param_result_t = self.types[0]
        try:
            r = param_result_t.decode(data)
        except ValueError:
            return
        _emit(event="result", update_seq=r.update_seq, key=r.key, value=r.value,
              applied=r.status == param_result_t.STATUS_APPLIED, cycle=r.cycle, reason=r.reason)

    def send_due(self):
        """Publishes every update, each with the state time it applies at, once the first state
        (the flight's time origin) is in."""
        while self.schedule and self.first is not None:
            when, key, value = self.schedule.pop(0)
            self.seq += 1
            p = self.types[1]()
            p.utime, p.seq, p.key, p.value = int(time.time() * 1e6), self.seq, key, value
            p.apply_utime = self.first + round(when * 1e6)
            self.lc.publish("MPPI_PARAMS", p.encode())
            _emit(event="sent", seq=self.seq, key=key, value=value, at_s=when, state_time_s=self.now)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="sitl_harness.inject")
    ap.add_argument("--lcm-url", required=True)
    ap.add_argument("--at", action="append", default=[], metavar="T:KEY=VALUE")
    a = ap.parse_args(argv)
    inj = Injector(a.lcm_url, sorted((parse_update(s) for s in a.at), key=lambda u: u[0]))
    # Subscribed: the harness starts the simulator only now, so the first state seen is the
    # flight's first (T counts from it; a lock-step flight runs seconds ahead of a late start).
    _emit(event="ready")
    running = {"on": True}
    signal.signal(signal.SIGTERM, lambda *_: running.update(on=False))
    errors = 0
    while running["on"]:
        try:
            inj.lc.handle_timeout(20)
        except OSError as e:
            if not running["on"]:
                break  # SIGTERM interrupted the wait
            errors += 1
            if errors <= 3:
                _emit(event="lcm_error", error=str(e))
            # The Python binding's udpm instance does not recover from a failed handle
            # (seen under lock-step bursts): a fresh one does.
            inj.lc = inj.connect()
        inj.send_due()
    _emit(event="end", state_time_s=inj.now, lcm_errors=errors,
          not_sent=[f"{t:g}:{k}={v:g}" for t, k, v in inj.schedule])
    return 0


if __name__ == "__main__":
    sys.exit(main())
