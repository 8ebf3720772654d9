"""Requests to mppid over LCM (param_update_t on MPPI_PARAMS) and its answers
(param_result_t on MPPI_PARAM_RESULT): `daemon.identify`, `daemon.restart_estimates`."""
from __future__ import annotations

import struct
import threading
import time


class MppidParams:
    def __init__(self, mppi_lcm, publish, channel: str, timeout_s: float):
        self.mppi_lcm, self.publish, self.channel, self.timeout_s = mppi_lcm, publish, channel, timeout_s
        self.cond = threading.Condition()
        self.seq = 0
        self.results = {}  # update seq -> param_result_t, mppid's answers to our requests

    def on_result(self, channel, data):
        try:
            r = self.mppi_lcm.param_result_t.decode(data)
        except (ValueError, struct.error):
            return
        with self.cond:
            self.results[r.update_seq] = r
            self.cond.notify_all()

    def ask(self, key: str, value: float) -> str:
        """A parameter update for mppid, and its answer: "" when applied, else why not."""
        msg = self.mppi_lcm.param_update_t()
        with self.cond:
            self.seq += 1
            msg.seq = self.seq
        msg.utime, msg.key, msg.value = int(time.time() * 1e6), key, float(value)
        self.publish(self.channel, msg.encode())
        deadline = time.monotonic() + self.timeout_s
        with self.cond:
            while msg.seq not in self.results and time.monotonic() < deadline:
                self.cond.wait(max(0.0, deadline - time.monotonic()))
            r = self.results.pop(msg.seq, None)
        if r is None:
            return "mppid did not answer (is it running on this LCM bus?)"
        if r.status != self.mppi_lcm.param_result_t.STATUS_APPLIED:
            return f"refused by mppid: {r.reason}"
        return ""
