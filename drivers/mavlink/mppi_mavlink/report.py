"""What the bridge reports: the link message on MPPI_MAVLINK_LINK (mavlink_link_t) and the
control socket's `status`, both read from the bridge's rooms."""
from __future__ import annotations

import time

from .forwarding import COUNTERS
from .state import wall_us


def link_message(b, msg):
    """Fills a mavlink_link_t from bridge `b`."""
    msg.utime = wall_us()
    ap, c = b.ap, b.counters
    msg.link_up, msg.link_losses, msg.dialect = int(ap.link_up), ap.link_losses, b.dialect
    age = ap.heartbeat_age()
    msg.heartbeat_age_s = -1.0 if age is None else float(age)
    msg.target_system, msg.armed, msg.mode = ap.target_system, int(ap.armed), ap.mode
    msg.streaming = int(b.fwd.streaming)
    for k in COUNTERS:
        if k.startswith(("dropped_", "setpoints_")) or k == "states_rejected":
            setattr(msg, k, c[k])
    thrust = b.checks.thrust
    msg.hover_thrust = float(thrust.hover) if thrust else -1.0
    msg.hover_source = b.checks.hover_source
    msg.battery_voltage = float(ap.battery_voltage)
    msg.battery_remaining = int(max(-1, min(100, ap.battery_remaining)))
    msg.error = b.checks.refusal or ""
    msg.engaged = int(b.engagement.forwarding)
    msg.state_rate_hz = float(b.states.rate.rate(time.monotonic()))
    msg.signing = int(b.link.signing_key is not None)
    sc = b.link.signing_counters()
    msg.rejected_unsigned, msg.rejected_bad_signature = sc["rejected_unsigned"], sc["rejected_bad_signature"]
    return msg


def status(b) -> dict:
    """The control socket's `status` of bridge `b`."""
    ap, e, age = b.ap, b.engagement.snapshot(), b.ap.heartbeat_age()
    thrust = b.checks.thrust
    return {"link_up": ap.link_up, "heartbeat_age_s": None if age is None else round(age, 3),
            "link_losses": ap.link_losses, "dialect": b.dialect, "target_system": ap.target_system,
            "armed": ap.armed, "mode": ap.mode, "streaming": b.fwd.streaming,
            "hover_thrust": thrust.hover if thrust else None, "hover_source": b.checks.hover_source,
            "refusal": b.checks.refusal, "battery_voltage": ap.battery_voltage,
            "engaged": e.forwarding, "engagement": e.state, "disengaged_why": e.why,
            "state_rate_hz": round(b.states.rate.rate(time.monotonic()), 1),
            "landed_state": ap.landed_state, "controller_healthy": b.fwd.last_status_healthy,
            "signing": b.link.signing_key is not None, **b.link.signing_counters(), **b.counters}
