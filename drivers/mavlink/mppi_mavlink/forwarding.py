"""mppid's commands -> the wire: each command_t through the gate (gate.py), converted (thrust
map, FLU -> FRD) and sent as one SET_ATTITUDE_TARGET at once, while engaged; mppid's status;
the counters by reason; whether the setpoint stream runs; the stream check `offboard` makes;
the trace of every forwarded setpoint. Nothing is ever re-sent or made up, but for one
setpoint: where the autopilot flies the last rate setpoint on (PX4, until COM_OF_LOSS_T), a
stream that stops while engaged ends with zero body rates at the last thrust, so that a pause
(mppid holding on a stale state, a stall) stops the vehicle turning instead of letting it fly
mppid's last rates for up to COM_OF_LOSS_T. The last thrust, not the hover thrust: tilted in a
fast turn, hover thrust would sink the vehicle (PX4 SITL, circle_5ms at 47 degrees: 0.27 s of
it cost 1 m/s of sink)."""
from __future__ import annotations

import json
import logging
import math
import struct
import threading
import time

from . import frames
from .layout import QuadrotorRate as Q
from .autopilots.base import mavlink
from .engagement import ENGAGED, PRESTREAM
from .gate import GateContext, gate, seq_restarted
from .state import mono_us

log = logging.getLogger("mppi_mavlink")
ATTITUDE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
COUNTERS = ("setpoints_sent", "dropped_not_advanced", "dropped_unhealthy", "dropped_nonfinite", "dropped_stale",
            "dropped_refused", "dropped_disengaged", "dropped_undecodable", "states_published", "states_rejected",
            "stop_setpoints_sent")


class Forwarder:
    def __init__(self, settings, mppi_lcm, link, ap, states, engagement, checks, on_stream_change):
        fw = settings["forwarding"]
        self.fw, self.offboard = fw, settings["offboard"]
        self.target_component = settings["mavlink"]["target_component"]
        self.mppi_lcm, self.link, self.ap, self.states = mppi_lcm, link, ap, states
        self.engagement, self.checks = engagement, checks
        self.counters = states.counters
        self.on_stream_change = on_stream_change       # (streaming, why): the link message
        self.on_mppid_restart = lambda: None
        self.status_timeout_us = int(fw["status_timeout_s"] * 1e6)
        self.max_state_age_us = int(fw["max_state_age_s"] * 1e6)
        self.restart_gap_us = int(fw["restart_gap_s"] * 1e6)
        self.last_cmd_seq = None
        self.last_status_mono = None
        self.last_status_healthy = False
        self.last_forward_mono = None
        self.last_thrust = None        # normalised, of the latest forwarded setpoint
        self.ready_since = None
        self.last_ready_mono = None
        self.ready_times = []  # monotonic us of recent commands that passed the gate (offboard's stream check)
        self.last_drop = ""    # why the latest command was not forwarded
        self.streaming = False
        self.stream_lock = threading.Lock()
        trace = settings["trace"]["file"]
        self.trace = open(trace, "a", buffering=1) if trace else None

    def context(self, cmd, now: int) -> GateContext:
        st = self.states.published(cmd.state_seq)
        return GateContext(now, self.last_cmd_seq, self.last_forward_mono, self.restart_gap_us, self.checks.refusal,
                           self.fw["forward_hold_plan"], self.last_status_mono, self.last_status_healthy,
                           self.status_timeout_us, None if st is None else st[0], self.max_state_age_us,
                           self.checks.thrust is not None, self.ap.link_up, self.ap.target_system)

    # ---- LCM thread ---------------------------------------------------------------------
    def on_status(self, channel, data):
        try:
            st = self.mppi_lcm.controller_status_t.decode(data)
        except (ValueError, struct.error):  # wrong type, or truncated: not a status
            return
        self.last_status_mono = mono_us()
        self.last_status_healthy = bool(st.healthy) and st.mode != 2

    def on_command(self, channel, data):
        now = mono_us()
        try:
            cmd = self.mppi_lcm.command_t.decode(data)
        except (ValueError, struct.error):  # wrong type (fingerprint), truncated, or n the bytes do not back
            self.counters["dropped_undecodable"] += 1
            return
        ctx = self.context(cmd, now)
        reason = gate(cmd, ctx)
        if reason != "not_advanced":
            self._seq_advanced(cmd.seq, ctx)
        if reason is None:
            self._note_ready(now)
            if not self.engagement.forwarding:
                reason = "disengaged"
        if reason is not None:
            self.counters["dropped_" + reason] += 1
            self.last_drop = reason
            if self.streaming and (self.last_forward_mono is None or now - self.last_forward_mono > 100_000):
                self.set_streaming(False, reason)
            return
        self._forward(cmd, now)

    def _seq_advanced(self, seq: int, ctx: GateContext):
        if seq_restarted(seq, ctx):
            log.warning("command seq stepped back %d -> %d after %.1f s of silence: mppid restarted",
                        ctx.last_cmd_seq, seq, (ctx.now_us - (ctx.last_forward_us or ctx.now_us)) / 1e6)
            self.on_mppid_restart()
        self.last_cmd_seq = seq

    def _note_ready(self, now):
        """A command that passed the gate: `offboard` checks the stream of these (forwarded or,
        while disengaged, not)."""
        if self.last_ready_mono is None or now - self.last_ready_mono > 500_000:
            self.ready_since = now
        self.last_ready_mono = now
        self.ready_times.append(now)
        if len(self.ready_times) > 512:
            del self.ready_times[:256]

    def _forward(self, cmd, received: int):
        thrust = self.checks.thrust.to_normalized(float(cmd.u[Q.THRUST]))
        rates = frames.flu_to_frd(tuple(float(c) for c in cmd.u[Q.BODY_RATES]))
        if not all(math.isfinite(c) for c in (thrust,) + tuple(rates)):  # the last gate before the encoder
            self.counters["dropped_nonfinite"] += 1
            return
        boot_ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        target = self.ap.target_system
        if not self.link.send(lambda mv: mv.set_attitude_target_send(
                boot_ms, target, self.target_component, ATTITUDE_IGNORE, [1.0, 0.0, 0.0, 0.0],
                rates[0], rates[1], rates[2], thrust)):
            return
        sent = mono_us()
        self.counters["setpoints_sent"] += 1
        self.last_forward_mono, self.last_thrust = sent, thrust
        if not self.streaming:
            self.set_streaming(True, "")
        if self.trace is not None:
            self._trace(cmd, received, sent, thrust, rates)

    def _trace(self, cmd, received: int, sent: int, thrust, rates):
        """One line per forwarded setpoint: its state's path through the bridge, stage by stage
        (monotonic us: the sample's arrival, the state's LCM publish begun and returned, the
        command's arrival, the setpoint sent) and mppid's own times (command_t age, compute)."""
        st = self.states.published(cmd.state_seq) or (0, 0, 0, 0)
        self.trace.write(json.dumps({"mono_us": sent, "cmd_seq": cmd.seq, "state_seq": cmd.state_seq,
                                     "state_time_usec": st[1], "state_pub_mono_us": st[0],
                                     "state_rx_mono_us": st[2], "state_pubdone_mono_us": st[3] if len(st) > 3 else 0,
                                     "cmd_rx_mono_us": received, "age_us": cmd.age_us,
                                     "compute_us": cmd.compute_us, "thrust": thrust, "rates_frd": rates}) + "\n")

    def set_streaming(self, on: bool, reason: str):
        with self.stream_lock:
            if self.streaming == on:
                return
            self.streaming = on
        if on:
            log.info("setpoint stream started")
        else:
            log.warning("setpoint stream stopped (%s)", reason or "no fresh command")
            self._stop_turning()
        self.on_stream_change(on, reason)

    def _stop_turning(self):
        """The stream stopped while engaged, on an autopilot that flies the last setpoint on:
        one setpoint of zero body rates at the last thrust (the module docstring)."""
        engaged = self.engagement.snapshot().state == ENGAGED   # not a pre-stream: the autopilot flies it
        if not (self.ap.profile.flies_last_setpoint and engaged and self.checks.thrust is not None):
            return
        thrust = self.last_thrust if self.last_thrust is not None else self.checks.thrust.hover
        boot_ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        target = self.ap.target_system
        if self.link.send(lambda mv: mv.set_attitude_target_send(
                boot_ms, target, self.target_component, ATTITUDE_IGNORE, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, thrust)):
            self.counters["stop_setpoints_sent"] += 1

    # ---- housekeeping and `offboard` ----------------------------------------------------
    def check_stream(self):
        """The stream stops when nothing went out for 200 ms."""
        if self.streaming and (self.last_forward_mono is None or mono_us() - self.last_forward_mono > 200_000):
            self.set_streaming(False, "no fresh command for 200 ms")

    def stream_ok(self) -> tuple[bool, str]:
        """Whether mppid's commands pass the gate fast enough and long enough for `offboard`
        (on PX4 they are on the wire already: the pre-stream)."""
        o = self.offboard
        now = mono_us()
        if self.ready_since is None or self.last_ready_mono is None or now - self.last_ready_mono > 500_000:
            return False, "no command stream (is mppid running, healthy and getting states?)"
        since = self.ready_since
        snap = self.engagement.snapshot()
        if snap.state == PRESTREAM:   # on the wire only since the pre-stream began (after a latch: now)
            since = max(since, int(self.engagement.since * 1e6))
        if now - since < o["prestream_s"] * 1e6:
            return False, f"stream only {(now - since) / 1e6:.2f} s old"
        window = [t for t in self.ready_times if now - t <= o["prestream_s"] * 1e6]
        rate = len(window) / o["prestream_s"]
        if rate < o["min_rate_hz"]:
            return False, f"stream at {rate:.1f} Hz, below {o['min_rate_hz']:g} Hz"
        return True, f"stream at {rate:.1f} Hz for {(now - self.ready_since) / 1e6:.1f} s"

    def close(self):
        if self.trace is not None:
            self.trace.close()
