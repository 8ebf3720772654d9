"""The forwarding gate, a pure function: `gate(command, context)` says why a command_t must not
reach the wire (a counter's name: not_advanced, refused, unhealthy, nonfinite, stale), or
None when it may. Everything it reads is in the `GateContext`, taken when the command arrived;
it changes nothing, so it is tested from a table (test/mavlink/test_gate.py).

In order: the seq must advance (a step back after `restart_gap_us` of silence is a restarted
mppid and passes); nothing refuses flight (the parameter and telemetry checks); a thrust+rates
command of a known mode; not MODE_FAILSAFE, nor MODE_HOLD_PLAN unless forwarded by settings;
mppid's latest status healthy and fresh; finite values; an answer to a state published less
than `max_state_age_us` ago; a thrust map, a link and an autopilot to send to.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .layout import QuadrotorRate as Q


@dataclass(frozen=True)
class GateContext:
    now_us: int
    last_cmd_seq: int | None = None       # the last command that passed the seq check
    last_forward_us: int | None = None    # when a setpoint last went out
    restart_gap_us: int = 1_000_000
    refusal: str = ""                     # why the bridge will not fly ('' when it may)
    forward_hold_plan: bool = True
    status_us: int | None = None          # mppid's latest controller_status_t: when ...
    status_healthy: bool = False          # ... and whether healthy (not MODE_FAILSAFE)
    status_timeout_us: int = 2_500_000
    state_published_us: int | None = None  # when the state the command answers was published
    max_state_age_us: int = 250_000
    thrust_known: bool = False
    link_up: bool = False
    target_system: int = 0


def seq_restarted(seq: int, ctx: GateContext) -> bool:
    """A seq that stepped back after a silence: mppid restarted (gate() lets it pass)."""
    return ctx.last_cmd_seq is not None and seq < ctx.last_cmd_seq


def _seq_reason(seq: int, ctx: GateContext) -> str | None:
    if ctx.last_cmd_seq is None or seq > ctx.last_cmd_seq:
        return None
    quiet = ctx.last_forward_us is None or ctx.now_us - ctx.last_forward_us > ctx.restart_gap_us
    if seq == ctx.last_cmd_seq or not quiet:
        return "not_advanced"
    return None


def _mode_reason(cmd, ctx: GateContext) -> str | None:
    if cmd.kind != cmd.KIND_THRUST_RATES or cmd.n < 4 or len(cmd.u) < 4:
        return "refused"
    if cmd.mode not in (cmd.MODE_NORMAL, cmd.MODE_HOLD_PLAN, cmd.MODE_FAILSAFE):
        return "refused"  # a mode this bridge does not know is never forwarded
    if cmd.mode == cmd.MODE_FAILSAFE or (cmd.mode == cmd.MODE_HOLD_PLAN and not ctx.forward_hold_plan):
        return "unhealthy"
    return None


def gate(cmd, ctx: GateContext) -> str | None:
    """Why `cmd` (an mppi_lcm.command_t) is not forwarded, or None."""
    reason = _seq_reason(cmd.seq, ctx)
    if reason:
        return reason
    if ctx.refusal:
        return "refused"
    reason = _mode_reason(cmd, ctx)
    if reason:
        return reason
    if ctx.status_us is None or ctx.now_us - ctx.status_us > ctx.status_timeout_us or not ctx.status_healthy:
        return "unhealthy"
    if not all(math.isfinite(float(c)) for c in cmd.u[:len(Q.COMMAND)]):
        return "nonfinite"
    if ctx.state_published_us is None or ctx.now_us - ctx.state_published_us > ctx.max_state_age_us:
        return "stale"
    if not ctx.thrust_known or not ctx.link_up or not ctx.target_system:
        return "refused"
    return None
