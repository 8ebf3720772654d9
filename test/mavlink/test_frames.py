"""Frame conversions (ENU/FLU <-> NED/FRD), the thrust map, the boot clock, parameters and
settings: pure functions, no processes."""
import math
import random
import struct

import pytest

from mppi_mavlink import frames, settings
from mppi_mavlink.bridge import _rotate, decode_param, mavlink
from mppi_mavlink.thrust import ThrustMap
from mavlink_vehicle import ned

A = ((0, 1, 0), (1, 0, 0), (0, 0, -1))
B = ((1, 0, 0), (0, -1, 0), (0, 0, -1))


def random_quat(rng):
    q = [rng.gauss(0, 1) for _ in range(4)]
    return frames.quat_normalize(q)


def close(a, b, tol=1e-9):
    return all(abs(x - y) <= tol for x, y in zip(a, b))


def same_rotation(q1, q2, tol=1e-9):
    return close(q1, q2, tol) or close(q1, [-c for c in q2], tol)


def test_vectors_swap_and_negate():
    assert frames.enu_to_ned((1.0, 2.0, 3.0)) == (2.0, 1.0, -3.0)      # east 1, north 2, up 3
    assert frames.ned_to_enu((2.0, 1.0, -3.0)) == (1.0, 2.0, 3.0)
    assert frames.flu_to_frd((0.1, 0.2, 0.3)) == (0.1, -0.2, -0.3)      # roll, pitch, yaw rates
    assert frames.frd_to_flu((0.1, -0.2, -0.3)) == (0.1, 0.2, 0.3)


def test_level_facing_east_is_yaw_90_in_ned():
    q = frames.q_enu_flu_to_ned_frd((1.0, 0.0, 0.0, 0.0))
    s = math.sqrt(0.5)
    assert close(q, (s, 0.0, 0.0, s))                  # 90 deg about down: facing east
    assert abs(frames.yaw_enu_to_ned(0.0) - math.pi / 2) < 1e-12
    assert abs(frames.yaw_ned_to_enu(0.0) - math.pi / 2) < 1e-12  # facing north in NED: 90 deg in ENU


def test_level_facing_north_is_identity_in_ned():
    s = math.sqrt(0.5)
    q_enu = (s, 0.0, 0.0, s)                            # yaw +90 deg ENU: facing north
    assert same_rotation(frames.q_enu_flu_to_ned_frd(q_enu), (1.0, 0.0, 0.0, 0.0))


def test_quaternion_matches_matrix_definition():
    """R_ned_frd = A R_enu_flu B for random attitudes, and the two implementations agree."""
    rng = random.Random(4)
    for _ in range(200):
        q = random_quat(rng)
        qn = frames.q_enu_flu_to_ned_frd(q)
        want = ned.matmul(ned.matmul(A, ned.quat_to_matrix(q)), B)
        got = ned.quat_to_matrix(qn)
        assert all(abs(got[i][j] - want[i][j]) < 1e-9 for i in range(3) for j in range(3))
        assert same_rotation(qn, ned.matrix_to_quat(want))
        assert same_rotation(frames.q_ned_frd_to_enu_flu(qn), q)
        assert qn[0] >= 0


def test_closed_form():
    rng = random.Random(5)
    s = math.sqrt(0.5)
    for _ in range(50):
        w, x, y, z = random_quat(rng)
        assert same_rotation(frames.q_enu_flu_to_ned_frd((w, x, y, z)), (s * (w + z), s * (x + y), s * (x - y), s * (w - z)))


def test_thrust_axis_and_rates_consistent():
    """A body vector seen in the world is the same physical vector in both conventions:
    R_ned (B v_flu) = A (R_enu v_flu); so the thrust axis (FLU +z = FRD -z) points up."""
    rng = random.Random(6)
    for _ in range(50):
        q = random_quat(rng)
        v_flu = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1))
        world_enu = _rotate(q, v_flu)
        world_ned = _rotate(frames.q_enu_flu_to_ned_frd(q), frames.flu_to_frd(v_flu))
        assert close(frames.enu_to_ned(world_enu), world_ned, 1e-9)
    # hover, level: thrust along FLU +z is world up, i.e. NED -z
    assert close(_rotate(frames.q_enu_flu_to_ned_frd((1, 0, 0, 0)), frames.flu_to_frd((0, 0, 1))), (0, 0, -1))


def test_vehicle_telemetry_round_trip():
    """The simulated autopilot's NED telemetry (matrices) read back by the bridge's
    conversion (quaternions) gives the truth back."""
    rng = random.Random(7)
    for _ in range(50):
        q = random_quat(rng)
        x = [rng.uniform(-5, 5) for _ in range(6)] + list(q) + [rng.uniform(-2, 2) for _ in range(3)]
        p, v, qn, vb, w = ned.state_to_ned(x)
        assert close(frames.ned_to_enu(p), x[0:3])
        assert close(frames.ned_to_enu(_rotate(qn, vb)), x[3:6], 1e-9)   # ODOMETRY: velocity in body FRD
        assert same_rotation(frames.q_ned_frd_to_enu_flu(qn), q)
        assert close(frames.frd_to_flu(w), x[10:13])


def test_quat_normalize_rejects_garbage():
    with pytest.raises(ValueError):
        frames.quat_normalize((0, 0, 0, 0))
    with pytest.raises(ValueError):
        frames.quat_normalize((math.nan, 0, 0, 1))


def test_thrust_map():
    m = ThrustMap(1.0, 9.81, 0.4)
    assert m.to_normalized(9.81) == pytest.approx(0.4)
    assert m.to_normalized(0.0) == 0.0
    assert m.to_normalized(100.0) == 1.0
    assert m.to_normalized(-3.0) == 0.0
    assert m.max_thrust == pytest.approx(24.525)
    assert m.to_newtons(m.to_normalized(12.0)) == pytest.approx(12.0)
    with pytest.raises(ValueError):
        m.to_normalized(math.nan)
    for bad in (0.0, 1.0, math.nan, -0.1):
        with pytest.raises(ValueError):
            ThrustMap(1.0, 9.81, bad)


def test_param_decoding():
    class M:
        pass
    m = M()
    m.param_type = mavlink.MAV_PARAM_TYPE_INT32
    m.param_value = struct.unpack("<f", struct.pack("<i", 8))[0]
    assert decode_param(m, mavlink.MAV_AUTOPILOT_PX4) == 8.0               # PX4: byte-wise
    m.param_value = 8.0
    assert decode_param(m, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA) == 8.0     # ArduPilot: cast
    m.param_type, m.param_value = mavlink.MAV_PARAM_TYPE_REAL32, 0.42
    assert decode_param(m, mavlink.MAV_AUTOPILOT_PX4) == pytest.approx(0.42)


def test_settings_validation():
    s = settings.load(None, ["vehicle.hover_thrust=0.35", "mavlink.dialect=ardupilot"])
    assert s["vehicle"]["hover_thrust"] == 0.35 and s["mavlink"]["dialect"] == "ardupilot"
    for bad, msg in (("mavlink.dialect=inav", "mavlink.dialect"), ("vehicle.hover_thrust=1.5", "vehicle.hover_thrust"),
                     ("offboard.min_rate_hz=2", "offboard.min_rate_hz"), ("vehicle.nope=1", "vehicle.nope"),
                     ("offboard.prestream_s=0.5", "offboard.prestream_s")):
        with pytest.raises(settings.SettingsError, match=msg.replace(".", r"\.")):
            settings.load(None, [bad])


def test_shipped_settings_load():
    from mavtest import ROOT
    for f in sorted((ROOT / "config" / "bridge").glob("*.yaml")):
        settings.load(f)


def test_tilt_is_the_angle_of_the_body_z_axis_from_the_vertical():
    for roll, pitch, yaw in [(0, 0, 0), (0, 0, 2.0), (0.3, 0, 0), (0, -0.5, 1.0), (0.4, 0.3, -2.5)]:
        cr, sr, cp, sp, cy, sy = (f(a / 2) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
        q = (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
             cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)
        want = math.degrees(math.acos(math.cos(roll) * math.cos(pitch)))  # z axis . vertical
        assert frames.tilt_deg(q) == pytest.approx(want, abs=1e-9)
        assert frames.tilt_deg(tuple(-c for c in q)) == pytest.approx(want, abs=1e-9)
