"""ArduPilot's state in two messages (mppi_mavlink/state.py): ATTITUDE_QUATERNION and
LOCAL_POSITION_NED of the same time_boot_ms are one state, whichever order they come in.
ArduCopter sends a slot's attitude *before* its position (ap_message order within a stream
bucket); pairing each attitude with the position held then made mppid's position a period
(20 ms at 50 Hz) older than the time it was stamped with. Each published state's position is
checked against the position of its own stamp, and its sample time against the autopilot's
clock."""
import os

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from mppi_mavlink import lcm_types  # noqa: E402
from mppi_mavlink.state import StatePublisher  # noqa: E402

mavlink = mavutil.mavlink
mppi_lcm = lcm_types.import_mppi_lcm()
SPEED = 5.0  # m/s north: the position of time t ms is 5 t / 1000 m


def publisher():
    out = []
    counters = {"states_rejected": 0, "states_published": 0}
    settings = {"vehicle": {"state_source": "split"}, "lcm": {"state_channel": "S"}}
    pub = StatePublisher(settings, mppi_lcm, lambda ch, data: out.append(mppi_lcm.vehicle_state_t.decode(data)),
                         counters)
    return pub, out, counters


def att(t_ms):
    return mavlink.MAVLink_attitude_quaternion_message(t_ms, 1.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3)


def lpn(t_ms):
    return mavlink.MAVLink_local_position_ned_message(t_ms, SPEED * t_ms / 1000.0, 0.0, -2.0, SPEED, 0.0, 0.0)


def north(state):
    return state.x[1]  # ENU: y is north


def fly(order, slots=50, period_ms=20):
    pub, out, counters = publisher()
    for k in range(1, slots + 1):
        t = 1000 + k * period_ms
        for m in order(t):
            pub.on_message(m.get_type(), m)
    return pub, out, counters


@pytest.mark.parametrize("name,order", [
    ("ArduPilot: attitude, then its position", lambda t: (att(t), lpn(t))),
    ("the simulated autopilot: position, then its attitude", lambda t: (lpn(t), att(t))),
    ("ArduPilot, the position 1 ms later", lambda t: (att(t), lpn(t + 1))),
])
def test_each_state_holds_the_position_of_its_own_time(name, order):
    pub, out, counters = fly(order)
    assert len(out) >= 48, name  # at most the first slot goes before the order is learnt
    for s in out[2:]:
        t_ms = (pub.published(s.seq)[1]) // 1000
        assert north(s) == pytest.approx(SPEED * t_ms / 1000.0, abs=SPEED * 0.0011), (name, t_ms)
    assert counters["states_rejected"] == 0


def test_a_position_of_another_time_is_carried_along_its_velocity():
    """Positions at 10 Hz, attitudes at 50 Hz (streams at other rates): each state's position is
    the latest one moved along its velocity to the attitude's time, never a stale one."""
    pub, out, _ = publisher()
    for k in range(1, 101):
        t = 1000 + 20 * k
        if k % 5 == 1:
            pub.on_message("LOCAL_POSITION_NED", lpn(t))
        pub.on_message("ATTITUDE_QUATERNION", att(t))
    assert len(out) >= 95
    for s in out[5:]:
        t_ms = pub.published(s.seq)[1] // 1000
        assert north(s) == pytest.approx(SPEED * t_ms / 1000.0, abs=1e-6)


def test_positions_that_stop_coming_stop_the_states():
    """Waiting for a position that never comes costs one state, then the attitude flies with the
    position it has (carried along) for 200 ms; after that, no state."""
    pub, out, counters = fly(lambda t: (att(t), lpn(t)), slots=20)
    n = len(out)
    for k in range(21, 40):
        pub.on_message("ATTITUDE_QUATERNION", att(1000 + 20 * k))
    assert counters["states_rejected"] == 1
    assert 0 < len(out) - n <= 11  # 200 ms of attitudes at most, none after
    last = out[-1]
    assert north(last) == pytest.approx(SPEED * (pub.published(last.seq)[1] // 1000) / 1000.0, abs=1e-6)


def test_the_sample_time_is_the_autopilots_not_the_arrival(monkeypatch):
    """Arrivals delayed by 0.3-5 ms, an attitude's position 0.1 ms after it: sample_utime is
    the autopilot's time on this clock (to the link's least delay), utime the publish time."""
    import random

    from mppi_mavlink import state
    wall0, rng, now = 1_764_000_000_000_000, random.Random(3), [0]
    monkeypatch.setattr(state, "wall_us", lambda: now[0])
    pub, out, _ = publisher()
    sent = {}
    for k in range(1, 200):
        t = 1000 + 20 * k
        now[0] = wall0 + t * 1000 + 300 + int(rng.uniform(0, 4700))
        pub.on_message("ATTITUDE_QUATERNION", att(t))
        now[0] += 100
        pub.on_message("LOCAL_POSITION_NED", lpn(t))
        sent[t * 1000] = wall0 + t * 1000
    late = [s.sample_utime - sent[pub.published(s.seq)[1]] for s in out[60:]]
    # the least delay (300 us) and the fit's slack; arrival is 2.65 ms late on average
    assert all(-500 <= d <= 1500 for d in late), (min(late), max(late))
    assert sum(late) / len(late) < 1000
    delays = [s.utime - s.sample_utime for s in out[60:]]
    assert max(delays) - min(delays) > 3000  # utime: when it was published, with the link's varying delay
