"""The map to the autopilot (drivers/mavlink/mppi_mavlink/obstacle_distance.py): a known map (a
trunk at a known bearing and distance from a known pose) gives the right sectors with the right
distance in cm and "no obstacle" elsewhere, in the body frame of a yawed vehicle too; the 3-D
points; the ticks on the autopilot's clock; the settings. No processes (the stand-in runs are in
test_obstacle_link.py)."""
import math

import numpy as np
import pytest

from mppi_mavlink import autopilots, lcm_types, settings
from mppi_mavlink.obstacle_distance import (SECTORS, UNKNOWN, ObstacleSender, Sectors, decode_map)

mppi_lcm = lcm_types.import_mppi_lcm()
FP = mppi_lcm.local_map_t._get_packed_fingerprint()
RES = 0.25
DIMS = (64, 64, 16)                 # 16 x 16 x 4 m
ORIGIN = (-8.0, -8.0, 0.0)
# The shipped defaults (min 0.2 m, band 1 m either way) but max_distance within the 16 m window.
SETS = ["obstacle_distance.max_distance_m=7.0"]
O = settings.load(None, SETS)["obstacle_distance"]
NO_OBSTACLE = int(round(O["max_distance_m"] * 100)) + 1


def trunk_map(trunks, dims=DIMS, origin=ORIGIN, seq=1):
    """local_map_t bytes: vertical trunks (x, y, radius) from z 0.3 m up, occupied cells -125 mm,
    the rest +2000 mm, as mppid-mapper encodes its field."""
    nx, ny, nz = dims
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    cx, cy, cz = (origin[0] + (i + 0.5) * RES, origin[1] + (j + 0.5) * RES, origin[2] + (k + 0.5) * RES)
    occ = np.zeros(dims[::-1], dtype=bool)
    for x, y, r in trunks:
        occ |= ((cx - x) ** 2 + (cy - y) ** 2 <= r * r) & (cz >= 0.3)
    m = mppi_lcm.local_map_t()
    m.utime, m.seq, m.origin, m.resolution = 1, seq, list(origin), RES
    m.nx, m.ny, m.nz, m.max_distance = nx, ny, nz, 5.0
    m.n_cells = nx * ny * nz
    m.distance_mm = np.where(occ, -125, 2000).ravel().tolist()   # index i + nx (j + ny k)
    return m.encode()


def quat_yaw(yaw_enu):
    return (math.cos(yaw_enu / 2), 0.0, 0.0, math.sin(yaw_enu / 2))


def sectors_of(trunks, p, yaw, **over):
    s = Sectors({**O, **over})
    cells = decode_map(trunk_map(trunks), FP, 0.0)
    s.compute(cells, p, quat_yaw(yaw))
    return s.distances.copy()


def sector_at(bearing_cw_deg):
    return round(bearing_cw_deg / 5.0) % SECTORS


def test_the_map_is_read_straight_from_its_encoding():
    cells = decode_map(trunk_map([(3.0, 1.0, 0.3)]), FP, 5.0)
    assert cells.n > 0 and cells.arrived == 5.0 and cells.seq == 1
    assert np.all(np.hypot(cells.xyz[:, 0] - 3.0, cells.xyz[:, 1] - 1.0) <= 0.3 + 1e-9)
    assert cells.xyz[:, 2].min() >= 0.3 and cells.xyz[:, 2].max() == pytest.approx(4.0 - RES / 2)
    assert list(cells.lo) == list(ORIGIN) and list(cells.hi) == [8.0, 8.0, 4.0]
    data = trunk_map([])
    with pytest.raises(ValueError, match="fingerprint"):
        decode_map(data, b"12345678", 0.0)
    with pytest.raises(ValueError, match="n_cells"):
        decode_map(data[:-2], FP, 0.0)


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, 30.0, -135.0, 180.0])
def test_a_trunk_lands_in_the_sector_of_its_bearing_from_the_nose(yaw_deg):
    """A trunk (0.3 m radius) 5 m east of a vehicle at 1 m height: its near face 4.7 m away,
    at the bearing east makes with the nose, clockwise (body FRD); every other sector free."""
    p, yaw = (0.0, 0.0, 1.0), math.radians(yaw_deg)
    d = sectors_of([(5.0, 0.0, 0.3)], p, yaw)
    bearing = math.degrees(yaw)                     # east is yaw radians clockwise of the nose
    j = sector_at(bearing)
    assert 460 <= d[j] <= 475, (j, d[j])            # 4.7 m less at most a cell's half-diagonal
    hit = np.flatnonzero(d != NO_OBSTACLE)
    assert set(hit) <= {(j - 1) % SECTORS, j, (j + 1) % SECTORS}, hit   # 0.3 m at 5 m: +-3.4 deg
    assert np.all(d[hit] >= d[j])


def test_two_trunks_a_yawed_vehicle_sees_them_where_they_stand():
    """Facing north (ENU yaw 90 deg): a trunk north is on the nose (sector 0), one west is to the
    left (270 deg clockwise: sector 54), 3 m and 6 m away."""
    d = sectors_of([(0.0, 3.0, 0.3), (-6.0, 0.0, 0.3)], (0.0, 0.0, 1.5), math.radians(90))
    assert 265 <= d[0] <= 275 and 565 <= d[54] <= 575
    assert d[18] == NO_OBSTACLE and d[36] == NO_OBSTACLE
    free = np.ones(SECTORS, bool)
    free[[71, 0, 1, 53, 54, 55]] = False
    assert np.all(d[free] == NO_OBSTACLE)


def test_the_height_band_and_the_distance_limits():
    # 1.0 m below the band: the vehicle at 6 m sees nothing of trunks that end at 4 m.
    assert np.all(sectors_of([(3.0, 0.0, 0.3)], (0.0, 0.0, 6.0), 0.0) == NO_OBSTACLE)
    # ... at 4.8 m the top cells (3.75-4 m) are within the band.
    assert sectors_of([(3.0, 0.0, 0.3)], (0.0, 0.0, 4.8), 0.0)[0] < NO_OBSTACLE
    # Beyond max_distance: free; nearer than min_distance: min_distance.
    assert np.all(sectors_of([(5.0, 0.0, 0.3)], (0.0, 0.0, 1.0), 0.0, max_distance_m=4.0) == 401)
    d = sectors_of([(0.5, 0.0, 0.3)], (0.0, 0.0, 1.0), 0.0, min_distance_m=0.5)
    assert d[0] == 50


def test_where_the_map_ends_before_max_distance_the_sector_is_unknown():
    """The window is 16 m wide around the origin: from (2, 0), east ends 6 m away, west 10 m."""
    d = sectors_of([], (2.0, 0.0, 1.0), 0.0)
    assert d[0] == UNKNOWN and d[36] == NO_OBSTACLE
    assert np.all(sectors_of([], (20.0, 0.0, 1.0), 0.0) == UNKNOWN)   # outside the window


def test_3d_points_are_the_nearest_cells_in_the_body_frame():
    s = Sectors(O)
    cells = decode_map(trunk_map([(0.0, 4.0, 0.3), (-2.0, 0.0, 0.3)]), FP, 0.0)
    pts = s.compute(cells, (0.0, 0.0, 1.0), quat_yaw(math.radians(90)), 16)   # facing north
    assert 2 <= len(pts) <= 16
    near = np.linalg.norm(pts, axis=1)
    assert np.all(np.diff(near) >= 0), "nearest first"
    x, y, z = pts[0]                     # the west trunk, 1.7 m to the left: FRD y < 0
    assert abs(x) < 0.3 and -1.9 < y < -1.5 and abs(z) <= 1.0
    ahead = [p for p in pts if p[0] > 3.4]
    assert ahead and all(abs(p[1]) < 0.5 for p in ahead)   # the north trunk on the nose
    assert len(s.compute(cells, (0.0, 0.0, 1.0), quat_yaw(0.0), 1)) == 1


class FakeLink:
    """The bridge's Link.send, onto a real pymavlink encoder; what went out, decoded."""

    def __init__(self):
        from pymavlink.dialects.v20 import all as dialect
        self.mav = dialect.MAVLink(None, srcSystem=1, srcComponent=191)
        self.mav.send = lambda m, force_mavlink1=False: self.sent.append(
            self.mav.decode(bytearray(m.pack(self.mav, force_mavlink1=False))))
        self.sent = []

    def send(self, fn):
        fn(self.mav)
        return True


def sender(dialect, **over):
    s = settings.load(None, SETS + [f"obstacle_distance.{k}={v}" for k, v in over.items()])
    link = FakeLink()
    return ObstacleSender(s, link, autopilots.load(dialect), {}, FP), link


def state_x(p=(0.0, 0.0, 1.0), yaw=0.0):
    return list(p) + [0.0] * 3 + list(quat_yaw(yaw)) + [0.0] * 3


@pytest.mark.parametrize("dialect", ["px4", "ardupilot"])
def test_the_messages_on_the_wire_and_3d_for_ardupilot_only(dialect):
    snd, link = sender(dialect)
    snd.on_map("MPPI_LOCAL_MAP", trunk_map([(5.0, 0.0, 0.3)]))
    assert snd.tick(2_000_000, (0.0, 0.0, 1.0), quat_yaw(0.0))
    od = [m for m in link.sent if m.get_type() == "OBSTACLE_DISTANCE"]
    od3 = [m for m in link.sent if m.get_type() == "OBSTACLE_DISTANCE_3D"]
    assert len(od) == 1
    m = od[0]
    assert m.time_usec == 2_000_000 and m.frame == 12 and m.angle_offset == 0.0   # MAV_FRAME_BODY_FRD
    assert m.increment == 5 and m.increment_f == 5.0 and m.min_distance == 20 and m.max_distance == 700
    assert 460 <= m.distances[0] <= 475 and m.distances[36] == 701
    if dialect == "ardupilot":
        assert od3 and all(p.time_boot_ms == 2000 and p.frame == 12 for p in od3)
        assert od3[0].x == pytest.approx(4.7, abs=0.25) and abs(od3[0].y) < 0.3
        assert [p.obstacle_id for p in od3] == list(range(len(od3)))
        assert snd.counters["obstacle_distance_3d_sent"] == len(od3)
    else:
        assert not od3
    assert snd.counters["obstacle_distance_sent"] == 1


def test_ticks_follow_the_autopilots_clock():
    """States at 50 Hz of the autopilot's clock for 3 s: 15 ticks in each second of that clock,
    stamped with their states' times; a sender thread that falls behind loses the oldest ticks
    beyond 8, counted; a clock that restarts starts the ticks again."""
    snd, _ = sender("px4", rate_hz=15)
    got = []
    for k in range(150):
        snd.on_state(1_000_000 + k * 20_000, state_x())
        while snd.ticks:
            got.append(snd.ticks.popleft()[0])
    assert list(np.bincount(np.array(got) // 1_000_000)[1:]) == [15, 15, 15], got
    assert all((t - 1_000_000) % 20_000 == 0 for t in got)
    snd.on_state(40_000, state_x())                      # the autopilot rebooted
    assert snd.ticks and snd.ticks[-1][0] == 40_000
    late, _ = sender("px4", rate_hz=15)
    for k in range(150):
        late.on_state(1_000_000 + k * 20_000, state_x())
    assert len(late.ticks) == 8 and late.counters["obstacle_ticks_dropped"] == 45 - 8
    assert late.ticks[-1][0] == 3_940_000


def test_a_stale_map_sends_nothing_and_is_counted(monkeypatch):
    snd, link = sender("ardupilot", max_map_age_s=0.5)
    assert not snd.tick(1_000_000, (0, 0, 1), quat_yaw(0)) and snd.counters["obstacle_no_map"] == 1
    snd.on_map("MPPI_LOCAL_MAP", trunk_map([(5.0, 0.0, 0.3)]))
    now = snd.latest[1]
    clock = [now + 0.4]
    monkeypatch.setattr("mppi_mavlink.obstacle_distance.time.monotonic", lambda: clock[0])
    assert snd.tick(1_066_667, (0, 0, 1), quat_yaw(0)) and len(link.sent) > 1
    sent = len(link.sent)
    clock[0] = now + 0.6
    assert not snd.tick(1_133_334, (0, 0, 1), quat_yaw(0))
    assert snd.counters["obstacle_stale"] == 1 and len(link.sent) == sent
    snd.on_map("MPPI_LOCAL_MAP", b"not a map")           # read at the next tick: refused, counted
    assert not snd.tick(1_200_000, (0, 0, 1), quat_yaw(0))
    assert snd.counters["obstacle_maps_rejected"] == 1 and snd.counters["obstacle_maps"] == 2
    assert snd.counters["obstacle_stale"] == 2 and snd.map.seq == 1


BAD = [("rate_hz", 5, "obstacle_distance.rate_hz"), ("max_distance_m", 700, "obstacle_distance.max_distance_m"),
       ("min_distance_m", 12, "obstacle_distance.min_distance_m"), ("enabled", "maybe", "obstacle_distance.enabled"),
       ("band_below_m", -1, "obstacle_distance.band_below_m"), ("max_3d_points", 2.5, "obstacle_distance.max_3d_points"),
       ("max_map_age_s", "nan", "obstacle_distance.max_map_age_s"), ("colour", 1, "obstacle_distance.colour")]


@pytest.mark.parametrize("key,value,field", BAD, ids=[b[0] for b in BAD])
def test_a_bad_setting_names_its_field(key, value, field):
    with pytest.raises(settings.SettingsError, match=field.replace(".", r"\.")):
        settings.load(None, [f"obstacle_distance.{key}={value}"])
