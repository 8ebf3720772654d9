"""The forwarding gate (mppi_mavlink/gate.py) from a table: one context that lets a command
through, and each row changes one thing and names the reason it must give. Pure: no process,
no network, no clock (the context carries `now`)."""
import dataclasses
import math

import pytest

from mppi_mavlink import lcm_types
from mppi_mavlink.gate import GateContext, gate, seq_restarted

C = lcm_types.import_mppi_lcm().command_t
NOW = 10_000_000


def command(seq=101, kind=C.KIND_THRUST_RATES, mode=C.MODE_NORMAL, u=(9.81, 0.1, -0.2, 0.3), state_seq=7):
    c = C()
    c.seq, c.kind, c.mode, c.state_seq = seq, kind, mode, state_seq
    c.n, c.u = len(u), list(u)
    return c


PASSING = GateContext(now_us=NOW, last_cmd_seq=100, last_forward_us=NOW - 20_000, restart_gap_us=1_000_000,
                      refusal="", forward_hold_plan=True, status_us=NOW - 100_000, status_healthy=True,
                      status_timeout_us=2_500_000, state_published_us=NOW - 30_000, max_state_age_us=250_000,
                      thrust_known=True, link_up=True, target_system=1)

ROWS = [
    # (what, command changes, context changes, reason)
    ("a good command", {}, {}, None),
    ("the first command ever", {}, {"last_cmd_seq": None}, None),
    ("seq repeated", {"seq": 100}, {}, "not_advanced"),
    ("seq back while streaming", {"seq": 99}, {}, "not_advanced"),
    ("seq repeated after a silence", {"seq": 100}, {"last_forward_us": NOW - 2_000_000}, "not_advanced"),
    ("seq back after a silence: mppid restarted", {"seq": 1}, {"last_forward_us": NOW - 2_000_000}, None),
    ("seq back, nothing ever forwarded", {"seq": 1}, {"last_forward_us": None}, None),
    ("a refusal to fly", {}, {"refusal": "GUID_OPTIONS=0"}, "refused"),
    ("motor speeds (another kind)", {"kind": 1}, {}, "refused"),
    ("an unknown kind", {"kind": -7}, {}, "refused"),
    ("three values", {"u": (9.81, 0.0, 0.0)}, {}, "refused"),
    ("an unknown mode", {"mode": 9}, {}, "refused"),
    ("MODE_FAILSAFE", {"mode": C.MODE_FAILSAFE}, {}, "unhealthy"),
    ("MODE_HOLD_PLAN, forwarded", {"mode": C.MODE_HOLD_PLAN}, {}, None),
    ("MODE_HOLD_PLAN, not forwarded", {"mode": C.MODE_HOLD_PLAN}, {"forward_hold_plan": False}, "unhealthy"),
    ("no status yet", {}, {"status_us": None}, "unhealthy"),
    ("status too old", {}, {"status_us": NOW - 2_600_000}, "unhealthy"),
    ("status unhealthy", {}, {"status_healthy": False}, "unhealthy"),
    ("NaN thrust", {"u": (math.nan, 0, 0, 0)}, {}, "nonfinite"),
    ("infinite rate", {"u": (9.81, 0, math.inf, 0)}, {}, "nonfinite"),
    ("an unknown state", {}, {"state_published_us": None}, "stale"),
    ("a state 0.3 s old", {}, {"state_published_us": NOW - 300_000}, "stale"),
    ("no thrust map", {}, {"thrust_known": False}, "refused"),
    ("link down", {}, {"link_up": False}, "refused"),
    ("no autopilot found", {}, {"target_system": 0}, "refused"),
    # Order: the seq check comes first, so a repeat is never counted as anything else.
    ("seq repeated and refused", {"seq": 100}, {"refusal": "x"}, "not_advanced"),
    ("refused and unhealthy", {"mode": C.MODE_FAILSAFE}, {"refusal": "x"}, "refused"),
]


@pytest.mark.parametrize("what,cmd_changes,ctx_changes,reason", ROWS, ids=[r[0] for r in ROWS])
def test_gate(what, cmd_changes, ctx_changes, reason):
    assert gate(command(**cmd_changes), dataclasses.replace(PASSING, **ctx_changes)) == reason


def test_restart_is_told_apart_from_an_advance():
    quiet = dataclasses.replace(PASSING, last_forward_us=NOW - 2_000_000)
    assert seq_restarted(1, quiet) and not seq_restarted(101, quiet)
    assert not seq_restarted(1, dataclasses.replace(PASSING, last_cmd_seq=None))


def test_gate_changes_nothing():
    ctx, cmd = PASSING, command()
    before = (dataclasses.asdict(ctx), cmd.encode())
    gate(cmd, ctx)
    assert (dataclasses.asdict(ctx), cmd.encode()) == before
