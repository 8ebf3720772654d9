"""The bridge adds no wait of its own (docs/latency.md, issue 31): a state goes to LCM inside
the handler of the MAVLink message that completes it, and a command goes to the wire inside
the handler of its LCM message, before the handler returns: no queue, no timer, no batch.
Checked by ordering and counters, not by time: a poll, a select timeout or a batching
re-introduced between arrival and send makes the send happen after the handler returned, and
these fail."""
import os
from types import SimpleNamespace

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mppi_mavlink import forwarding, lcm_types  # noqa: E402
from mppi_mavlink.settings import DEFAULTS  # noqa: E402
from mppi_mavlink.state import StatePublisher, mono_us  # noqa: E402

mavlink = mavutil.mavlink
mppi_lcm = lcm_types.import_mppi_lcm()


class Wire:
    """Records, in order, what the handlers under test did."""

    def __init__(self):
        self.events = []

    def send(self, fn):
        fn(SimpleNamespace(set_attitude_target_send=lambda *a: self.events.append(("setpoint", a))))
        return True


def test_a_state_is_published_inside_the_handler_of_the_message_that_completes_it():
    events = []
    counters = {"states_rejected": 0, "states_published": 0}
    pub = StatePublisher({"vehicle": {"state_source": "split"}, "lcm": {"state_channel": "S"}}, mppi_lcm,
                         lambda ch, data: events.append("published"), counters)
    for k in range(1, 20):  # ArduPilot's order: a burst's attitude, then its position
        t = 1000 + 20 * k
        events.append("attitude in")
        pub.on_message("ATTITUDE_QUATERNION", mavlink.MAVLink_attitude_quaternion_message(t, 1, 0, 0, 0, 0, 0, 0))
        events.append("position in")
        pub.on_message("LOCAL_POSITION_NED", mavlink.MAVLink_local_position_ned_message(t, 1, 2, -3, 0, 0, 0))
    # From the third burst on (the order learnt), each state is published in the position's handler.
    tail = events[-3 * 10:]
    assert tail == ["attitude in", "position in", "published"] * 10
    assert counters["states_published"] == 18  # the first burst has no position yet


def fake_forwarder(tmp_path, wire):
    s = {k: dict(v) if isinstance(v, dict) else v for k, v in DEFAULTS.items()}
    s["trace"] = {"file": str(tmp_path / "trace.jsonl")}
    published = {7: (mono_us(), 1_000_000, mono_us(), mono_us())}
    states = SimpleNamespace(published=published.get, counters=dict.fromkeys(forwarding.COUNTERS, 0))
    checks = SimpleNamespace(refusal="", thrust=SimpleNamespace(to_normalized=lambda n: n / 25.0))
    ap = SimpleNamespace(link_up=True, target_system=1)
    fwd = forwarding.Forwarder(s, mppi_lcm, wire, ap, states, SimpleNamespace(forwarding=True), checks,
                               lambda on, why: wire.events.append(("stream", on)))
    status = mppi_lcm.controller_status_t()
    status.healthy, status.mode = True, 0
    fwd.on_status("MPPI_STATUS", status.encode())
    return fwd


def command(seq):
    c = mppi_lcm.command_t()
    c.seq, c.state_seq, c.kind, c.mode, c.n = seq, 7, c.KIND_THRUST_RATES, c.MODE_NORMAL, 4
    c.u = [9.81, 0.1, 0.0, 0.0]
    return c.encode()


def test_a_command_goes_to_the_wire_inside_its_lcm_handler(tmp_path):
    wire = Wire()
    fwd = fake_forwarder(tmp_path, wire)
    for seq in range(1, 6):
        wire.events.append(("command in", seq))
        fwd.on_command("MPPI_COMMAND", command(seq))
        wire.events.append(("handler returned", seq))
    fwd.close()
    setpoints = [e for e in wire.events if e[0] in ("command in", "setpoint", "handler returned")]
    # in, out, returned: for every command, in that order
    assert [e[0] for e in setpoints] == ["command in", "setpoint", "handler returned"] * 5
    assert fwd.counters["setpoints_sent"] == 5
    # the trace says so too: each setpoint sent after its command's arrival, every stage stamped
    import json
    rows = [json.loads(line) for line in (tmp_path / "trace.jsonl").read_text().splitlines()]
    assert len(rows) == 5 and all(r["cmd_rx_mono_us"] <= r["mono_us"] and r["state_rx_mono_us"] for r in rows)


def test_the_lcm_thread_blocks_on_the_socket_not_a_timer(monkeypatch):
    """The bridge's LCM loop waits in LCM's handle_timeout (a select on its socket: it returns
    as a message arrives); its timeout only lets it see `stop`. A sleep or a poll in that loop
    would be a wait between a command's arrival and its send. The loop is run on a bus of its
    own and watched: every message is handled by a blocking wait that was already under way
    when it was published, nothing sleeps, and no call polls (a zero timeout)."""
    import threading
    import time as time_module

    import lcm

    from mppi_mavlink import bridge
    slept = []
    monkeypatch.setattr(time_module, "sleep", lambda s: slept.append(s))
    lc = lcm.LCM("memq://")
    calls, handled, waiting = [], [], threading.Event()

    class Watched:
        def handle_timeout(self, ms):
            calls.append(ms)
            waiting.set()
            return lc.handle_timeout(ms)
    loop = SimpleNamespace(stop=threading.Event(), lc=Watched())
    lc.subscribe("C", lambda ch, data: handled.append((data, len(calls))))
    th = threading.Thread(target=bridge.Bridge._lcm_loop, args=(loop,), daemon=True)
    th.start()
    try:
        for k in range(20):
            waiting.clear()
            assert waiting.wait(10), "the loop never waited on the bus"
            in_call = len(calls)
            lc.publish("C", bytes([k]))
            deadline = time_module.monotonic() + 10
            while len(handled) <= k and time_module.monotonic() < deadline:
                threading.Event().wait(0.001)
            assert len(handled) == k + 1, "a message was not handled"
            assert handled[k][1] == in_call, "handled by a later call: the wait did not return on arrival"
    finally:
        loop.stop.set()
        th.join(5)
    assert slept == [] and min(calls) >= 10, (slept, min(calls))
