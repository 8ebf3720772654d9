"""Property tests (hypothesis) of the bridge's pure parts and of its two paths fed generated
input, with no process and no network:

* frames: every conversion is its own inverse (on one vector and on columns of samples),
  attitudes survive the round trip, and a body vector is the same physical vector in both
  conventions, for any attitude;
* the thrust map: clamped to [0, 1], monotone, exact at hover, invertible in range;
* MAVLink -> state: telemetry of every kind the bridge reads, with any field values (NaN,
  infinities, zero quaternions, huge numbers, odd frames), encoded and parsed by pymavlink,
  into Bridge._on_mavlink: it never raises, and every vehicle_state_t it publishes is 13
  finite values with a unit quaternion (w >= 0);
* command -> MAVLink: generated command_t (any kind, mode, size, values) and damaged
  encodings into Bridge's forwarding (Forwarder.on_command): it never raises, and the bytes it puts on the wire,
  parsed afresh, are exactly one SET_ATTITUDE_TARGET per command the gate lets through,
  finite, thrust in [0, 1], rates the command's in FRD.

Deterministic in CI (derandomize); MPPID_HYPOTHESIS_EXAMPLES scales the number of examples.
"""
import math
import os
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mppi_mavlink import bridge as bridge_mod  # noqa: E402
from mppi_mavlink import frames, lcm_types  # noqa: E402
from mppi_mavlink import settings as settings_mod  # noqa: E402
from mppi_mavlink.thrust import ThrustMap  # noqa: E402

mavlink = mavutil.mavlink
EXAMPLES = int(os.environ.get("MPPID_HYPOTHESIS_EXAMPLES", "300"))
PROP = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)
f32 = st.floats(width=32)  # anything a MAVLink float field can carry: NaN, +-inf, huge, subnormal
vec3 = st.tuples(finite, finite, finite)


def unit_quat(q):
    n = math.sqrt(sum(c * c for c in q))
    assume(n > 1e-3)
    return frames.quat_normalize(q)


quats = st.tuples(finite, finite, finite, finite).map(unit_quat)


def close(a, b, tol):
    return all(abs(x - y) <= tol * max(1.0, abs(x), abs(y)) for x, y in zip(a, b))


def same_rotation(a, b, tol=1e-9):
    return close(a, b, tol) or close(a, [-c for c in b], tol)


# ---- frames -------------------------------------------------------------------------------

@PROP
@given(vec3)
def test_vector_maps_are_their_own_inverse(v):
    assert frames.ned_to_enu(frames.enu_to_ned(v)) == v
    assert frames.frd_to_flu(frames.flu_to_frd(v)) == v
    ned = frames.enu_to_ned(v)
    assert (ned[0], ned[1], ned[2]) == (v[1], v[0], -v[2])


@PROP
@given(st.lists(vec3, min_size=1, max_size=16))
def test_vector_maps_take_columns_of_samples(rows):
    """The log readers convert whole columns at once (numpy arrays for x, y, z): row by row the
    same, and back again the identity."""
    cols = np.array(rows, dtype=np.float64).T
    enu = np.stack(frames.ned_to_enu(cols), axis=1)
    assert enu.tolist() == [list(frames.ned_to_enu(r)) for r in rows]
    assert np.stack(frames.enu_to_ned(enu.T), axis=1).tolist() == [list(r) for r in rows]
    flu = np.stack(frames.frd_to_flu(cols), axis=1)
    assert flu.tolist() == [list(frames.frd_to_flu(r)) for r in rows]


@PROP
@given(quats)
def test_attitude_round_trip_and_form(q):
    qn = frames.q_enu_flu_to_ned_frd(q)
    assert abs(sum(c * c for c in qn) - 1.0) < 1e-12 and qn[0] >= 0.0
    assert same_rotation(frames.q_ned_frd_to_enu_flu(qn), q)
    w, x, y, z = q
    s = math.sqrt(0.5)
    assert same_rotation(qn, (s * (w + z), s * (x + y), s * (x - y), s * (w - z)))


@PROP
@given(quats, vec3)
def test_a_body_vector_is_the_same_physical_vector_in_both_conventions(q, v):
    world_enu = bridge_mod._rotate(q, v)
    world_ned = bridge_mod._rotate(frames.q_enu_flu_to_ned_frd(q), frames.flu_to_frd(v))
    assert close(frames.enu_to_ned(world_enu), world_ned, 1e-9)


@PROP
@given(st.floats(min_value=-1e3, max_value=1e3))
def test_heading_map_is_its_own_inverse(yaw):
    back = frames.yaw_ned_to_enu(frames.yaw_enu_to_ned(yaw))
    d = math.remainder(back - yaw, 2 * math.pi)
    assert abs(d) < 1e-9


@PROP
@given(st.tuples(f32, f32, f32, f32))
def test_quat_normalize_gives_a_rotation_or_refuses(q):
    try:
        n = frames.quat_normalize(q)
    except ValueError:
        norm = math.sqrt(sum(c * c for c in q)) if all(math.isfinite(c) for c in q) else math.nan
        assert not math.isfinite(norm) or norm < 1e-9
        return
    assert all(math.isfinite(c) for c in n) and abs(sum(c * c for c in n) - 1.0) < 1e-9 and n[0] >= 0.0


# ---- thrust map ---------------------------------------------------------------------------

maps = st.builds(ThrustMap, st.floats(1e-3, 1e4), st.floats(0.1, 100.0), st.floats(0.011, 0.989))


@PROP
@given(maps, st.floats(allow_nan=False, allow_infinity=False), st.floats(allow_nan=False, allow_infinity=False))
def test_thrust_map_is_clamped_and_monotone(m, t1, t2):
    a, b = m.to_normalized(min(t1, t2)), m.to_normalized(max(t1, t2))
    assert 0.0 <= a <= b <= 1.0


@PROP
@given(maps, st.floats(0.0, 1.0))
def test_thrust_map_hover_and_round_trip(m, frac):
    assert m.to_normalized(m.weight) == pytest.approx(m.hover, rel=1e-12)
    t = frac * m.max_thrust
    assert m.to_newtons(m.to_normalized(t)) == pytest.approx(t, rel=1e-9, abs=1e-12)


@PROP
@given(maps, st.sampled_from([math.nan, math.inf, -math.inf]))
def test_thrust_map_refuses_non_finite(m, t):
    with pytest.raises(ValueError):
        m.to_normalized(t)


@PROP
@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True),
       st.floats(allow_nan=True, allow_infinity=True))
def test_thrust_map_accepts_only_usable_parameters(mass, g, h):
    ok = all(math.isfinite(v) and v > 0 for v in (mass, g, h)) and h < 1.0
    if ok:
        ThrustMap(mass, g, h)
    else:
        with pytest.raises(ValueError):
            ThrustMap(mass, g, h)


# ---- the bridge, in process -------------------------------------------------------------

class Wire:
    """Where the bridge's MAVLink encoder writes: the bytes, to be parsed afresh."""

    def __init__(self):
        self.data = bytearray()

    def write(self, b):
        self.data += b

    def messages(self):
        rx = mavlink.MAVLink(None)
        rx.robust_parsing = True
        return [m for m in rx.parse_buffer(bytes(self.data)) or [] if m.get_type() != "BAD_DATA"]


class FakeLcm:
    def __init__(self):
        self.sent = []

    def publish(self, channel, data):
        self.sent.append((channel, data))


class FakeConn:
    def __init__(self, wire):
        self.mav = mavlink.MAVLink(wire, srcSystem=1, srcComponent=191)


def make_bridge():
    s = settings_mod.load(None, ["vehicle.hover_thrust=0.4", "vehicle.mass=1.0"])
    b = bridge_mod.Bridge(s, lcm_url="memq://")
    b.lc = FakeLcm()
    b.wire = Wire()
    b.link.mav = FakeConn(b.wire)
    b.ap.link_up, b.ap.target_system, b.checks.param_refusal = True, 1, ""
    b.fwd.last_status_mono, b.fwd.last_status_healthy = bridge_mod.mono_us(), True
    return b


def states(b):
    mppi_lcm = lcm_types.import_mppi_lcm()
    return [mppi_lcm.vehicle_state_t.decode(d) for ch, d in b.lc.sent if ch == "MPPI_STATE"]


frame_ids = st.sampled_from([mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD, mavlink.MAV_FRAME_BODY_FRD,
                             mavlink.MAV_FRAME_BODY_NED, 0, 99])
cov = st.just([math.nan] + [0.0] * 20)


def telemetry(tx):
    """One MAVLink message of a kind the bridge reads, any field values."""
    return st.one_of(
        st.builds(tx.odometry_encode, st.integers(0, 2**64 - 1), frame_ids, frame_ids, f32, f32, f32,
                  st.lists(f32, min_size=4, max_size=4), f32, f32, f32, f32, f32, f32, cov, cov),
        st.builds(tx.attitude_quaternion_encode, st.integers(0, 2**32 - 1), f32, f32, f32, f32, f32, f32, f32),
        st.builds(tx.local_position_ned_encode, st.integers(0, 2**32 - 1), f32, f32, f32, f32, f32, f32),
        st.builds(tx.heartbeat_encode, st.integers(0, 255), st.integers(0, 255), st.integers(0, 255),
                  st.integers(0, 2**32 - 1), st.integers(0, 255)),
        st.builds(tx.sys_status_encode, st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1),
                  st.integers(0, 2**32 - 1), st.integers(0, 1000), st.integers(0, 65535), st.integers(-32768, 32767),
                  st.integers(-128, 127), st.integers(0, 65535), st.integers(0, 65535), st.integers(0, 65535),
                  st.integers(0, 65535), st.integers(0, 65535), st.integers(0, 65535)),
        st.builds(tx.param_value_encode, st.binary(min_size=0, max_size=16), f32, st.integers(1, 10),
                  st.integers(0, 65535), st.integers(0, 65535)),
        st.builds(tx.statustext_encode, st.integers(0, 7), st.binary(min_size=0, max_size=50)),
        st.builds(tx.command_ack_encode, st.integers(0, 65535), st.integers(0, 255)),
    )


@PROP
@given(st.data())
def test_mavlink_to_state_publishes_only_finite_unit_states(data):
    b = make_bridge()
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    rx = mavlink.MAVLink(None)
    rx.robust_parsing = True
    msgs = data.draw(st.lists(telemetry(tx), min_size=1, max_size=12))
    for m in msgs:
        for parsed in rx.parse_buffer(m.pack(tx)) or []:
            b._on_mavlink(parsed)  # must not raise, whatever the values
    out = states(b)
    for s in out:
        assert (s.model, s.vehicle_count, s.nx, s.n, len(s.x)) == (2, 1, 13, 13, 13)
        assert all(math.isfinite(c) for c in s.x)
        q = s.x[6:10]
        assert abs(sum(c * c for c in q) - 1.0) < 1e-5 and q[0] >= 0.0
    assert [s.seq for s in out] == list(range(1, len(out) + 1))
    published = len(out) + b.counters["states_rejected"]
    readable = [m for m in msgs if m.get_type() == "ODOMETRY" and m.frame_id in
                (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD)]
    assert published >= len(readable)  # every readable ODOMETRY is either a state or counted


@PROP
@given(vec3, vec3, quats, vec3, st.integers(0, 2**40))
def test_odometry_becomes_the_enu_state(p, v, q, w, t_us):
    """A good ODOMETRY (LOCAL_NED, body FRD velocity) gives exactly one state: position and
    attitude converted, the body velocity rotated into the world, rates into FLU."""
    b = make_bridge()
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    q_ned = frames.q_enu_flu_to_ned_frd(q)
    v_ned = frames.enu_to_ned(v)
    v_body = bridge_mod._rotate(frames.quat_conj(q_ned), v_ned)
    w_frd = frames.flu_to_frd(w)
    m = tx.odometry_encode(t_us, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, *frames.enu_to_ned(p),
                           list(q_ned), *v_body, *w_frd, [math.nan] + [0.0] * 20, [math.nan] + [0.0] * 20)
    rx = mavlink.MAVLink(None)
    for parsed in rx.parse_buffer(m.pack(tx)):
        b._on_mavlink(parsed)
    (s,) = states(b)
    f = lambda x: struct.unpack("f", struct.pack("f", x))[0]  # noqa: E731  (MAVLink carries float32)
    assert close(s.x[0:3], [f(c) for c in p], 1e-6)
    # The body velocity and the attitude each went through float32: errors scale with |v|.
    scale = max(1.0, math.sqrt(sum(c * c for c in v)))
    assert all(abs(a - b) <= 1e-6 * scale for a, b in zip(s.x[3:6], v))
    assert same_rotation(s.x[6:10], q, 1e-5)
    assert close(s.x[10:13], [f(c) for c in w], 1e-6)


def command_bytes(mppi_lcm, seq, kind, mode, u, state_seq):
    c = mppi_lcm.command_t()
    c.utime, c.seq, c.state_seq, c.mode, c.kind = 0, seq, state_seq, mode, kind
    c.n, c.u = len(u), list(u)
    return c.encode()


def damaged(data, how, at, byte):
    if how == "truncate":
        return data[:at % max(1, len(data))]
    if how == "flip":
        i = at % len(data)
        return data[:i] + bytes([data[i] ^ (byte or 1)]) + data[i + 1:]
    if how == "append":
        return data + bytes([byte])
    return data


commands = st.tuples(st.sampled_from([2, 2, 2, 1, 3, -7]), st.sampled_from([0, 0, 1, 2, 9]),
                     st.lists(f32, min_size=0, max_size=7), st.booleans(),
                     st.sampled_from(["intact"] * 6 + ["truncate", "flip", "append"]), st.integers(0, 10_000),
                     st.integers(0, 255))


@PROP
@given(st.lists(commands, min_size=1, max_size=10))
@example([(2, 9, [0.0, 0.0, 0.0, 0.0], True, "intact", 0, 0)])  # a mode the bridge does not know (found by CI)
def test_command_to_mavlink_is_finite_clamped_and_gated(cmds):
    b = make_bridge()
    mppi_lcm = b.mppi_lcm
    b.states.times[7] = (bridge_mod.mono_us(), 0)  # a state the bridge published just now
    expected = []
    for i, (kind, mode, u, known, how, at, byte) in enumerate(cmds):
        data = command_bytes(mppi_lcm, 100 + i, kind, mode, u, 7 if known else 12345)
        bad = damaged(data, how, at, byte)
        b.fwd.on_command("MPPI_COMMAND", bad)  # must not raise
        if bad != data:
            continue  # damaged bytes may still decode to something; the checks below cover what goes out
        if kind == 2 and len(u) >= 4 and mode in (0, 1) and known and all(math.isfinite(c) for c in u[:4]):
            expected.append(u[:4])
    out = [m for m in b.wire.messages() if m.get_type() == "SET_ATTITUDE_TARGET"]
    for m in out:
        assert m.type_mask == 128 and m.target_system == 1
        assert 0.0 <= m.thrust <= 1.0
        assert all(math.isfinite(c) for c in (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate))
    if all(how == "intact" for *_, how, _at, _b in cmds):
        assert len(out) == len(expected)
        for m, u in zip(out, expected):
            assert m.thrust == pytest.approx(min(1.0, max(0.0, 0.4 * u[0] / 9.81)), abs=1e-6)
            assert (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate) == (u[1], -u[2], -u[3])
    assert b.counters["setpoints_sent"] == len(out)


@PROP
@given(st.binary(max_size=200))
def test_garbage_on_the_command_and_status_channels_is_counted(data):
    b = make_bridge()
    before = dict(b.counters)
    b.fwd.on_command("MPPI_COMMAND", data)
    b.fwd.on_status("MPPI_STATUS", data)
    assert b.wire.messages() == []
    assert sum(b.counters.values()) == sum(before.values()) + 1  # the command: counted once, by reason
    assert b.counters["setpoints_sent"] == 0

