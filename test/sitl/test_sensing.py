"""Sensed flights (docs/sensing.md): the harness starts mppid-mapper with the sensors on a bus
of their own and keeps their frames out of the log; the score names, per tree, when it first
entered the map and the closest approach."""
from __future__ import annotations

import json

import numpy as np
from conftest import missing
from sitl_helpers import ROOT  # noqa: F401  (puts this checkout's tools/ first on sys.path)

from sitl_harness import paths, sensing
from sitl_harness.flights.base import FlightSpec, lcm_url_for_port
from sitl_harness.flights.sim import SimFlight, sensor_bus


def test_sensor_bus_is_the_next_port_with_a_receive_buffer():
    assert sensor_bus("udpm://239.255.76.67:7667?ttl=0") == "udpm://239.255.76.67:7668?ttl=0&recv_buf_size=4194304"
    assert sensor_bus(lcm_url_for_port(65535)).startswith("udpm://239.255.76.67:65534?")


def test_sensed_flight_starts_the_mapper_and_logs_no_frames(tmp_path):
    if paths.find_binary("mppid-mapper") is None or paths.find_binary("mppid-sim") is None:
        missing("mppid-mapper or mppid-sim not built")
    spec = FlightSpec(scenario="forest_4m_sensed", seed=5, out=tmp_path, realtime=True, controller="standin")
    cmds = SimFlight(spec).plan().commands
    bus = sensor_bus(spec.lcm_url)
    mapper = cmds["mapper"]
    assert mapper[mapper.index("--sensor-lcm-url") + 1] == bus
    assert mapper[mapper.index("--config") + 1] == str(ROOT / "config/mapper/mapper.yaml")
    assert mapper[mapper.index("--sensed") + 1] == str(tmp_path / "sensed.jsonl")
    sim = cmds["sim"]
    assert sim[sim.index("--sensor-lcm-url") + 1] == bus
    flown = SimFlight(FlightSpec(scenario="forest_4m_sensed", out=tmp_path, realtime=True)).plan().commands
    if paths.find_binary("mppid") is not None:  # the controller takes the 1 MB maps: a buffer for them
        ctrl = flown["controller"]
        assert ctrl[ctrl.index("--lcm-url") + 1] == spec.lcm_url + "&recv_buf_size=4194304"
    logger = cmds["logger"]
    assert "--channel=^(?!(MPPI_DEPTH|MPPI_LIDAR|MPPI_LOCAL_MAP)$).*" in logger
    # The known-map forest: no mapper, no sensor bus, everything logged.
    known = SimFlight(FlightSpec(scenario="forest_4m", out=tmp_path, realtime=True, controller="standin")).plan()
    assert "mapper" not in known.commands and "--sensor-lcm-url" not in known.commands["sim"]
    assert not any(a.startswith("--channel") for a in known.commands["logger"])


def _write_flight(out, trees, sensed_lines, path_xy, t):
    (out / "world.json").write_text(json.dumps({"obstacles": trees}))
    (out / "mapper_stats.json").write_text(json.dumps({"resolution": 0.25, "frames": 30, "maps": 10}))
    (out / "sim_summary.json").write_text(json.dumps({"sensors": {"depth_camera": {"frames": 30}}}))
    (out / "sensed.jsonl").write_text("".join(json.dumps(r) + "\n" for r in sensed_lines) + '{"t": 9, "cut')
    X = np.zeros((len(t), 16))
    X[:, :2] = path_xy
    return X


def test_score_names_each_passed_tree_its_first_sighting_and_closest_approach(tmp_path):
    trees = [[10.0, 1.0, 0.3, 0, 0], [20.0, -0.6, 0.4, 0, 0], [30.0, 8.0, 0.3, 0, 0]]
    sensed_lines = [{"t": 0.5, "utime": 1, "sensor": [2.0, 0.0, 2.0], "columns": [[9.875, 0.875], [5.0, 5.0]]},
                    {"t": 2.0, "utime": 2, "sensor": [14.0, 0.0, 2.0], "columns": [[19.625, -0.625]]}]
    t = np.linspace(0.0, 4.0, 401)
    xy = np.stack([10.0 * t, np.zeros_like(t)], axis=1)  # along y = 0 at 10 m/s
    X = _write_flight(tmp_path, trees, sensed_lines, xy, t)
    s = sensing.sensing_figures(tmp_path, {"obstacles": trees}, t, X)["sensing"]
    assert s["trees"] == 3 and s["trees_sensed"] == 2
    assert s["passed"] == 2 and s["passed_unsensed"] == []  # the third tree is 8 m off the path
    a, b = s["per_tree"]
    assert a["tree"] == 0 and a["first_sensed_t"] == 0.5 and abs(a["closest_m"] - 0.7) < 1e-6
    assert abs(a["first_sensed_range_m"] - (np.hypot(8.0, 1.0) - 0.3)) < 0.01 and abs(a["closest_t"] - 1.0) < 0.011
    assert b["first_sensed_t"] == 2.0 and abs(b["closest_m"] - 0.2) < 1e-6
    assert s["min_warning_s"] == 0.0  # tree 1 entered the map at 2.0 s, passed at 2.0 s: no warning
    assert s["mapper"]["frames"] == 30 and s["sensors"]["depth_camera"]["frames"] == 30


def test_score_names_a_passed_tree_never_sensed(tmp_path):
    trees = [[10.0, 1.0, 0.3, 0, 0]]
    t = np.linspace(0.0, 2.0, 201)
    X = _write_flight(tmp_path, trees, [], np.stack([10.0 * t, np.zeros_like(t)], axis=1), t)
    s = sensing.sensing_figures(tmp_path, {"obstacles": trees}, t, X)["sensing"]
    assert s["trees_sensed"] == 0 and s["passed_unsensed"] == [0] and s["min_warning_s"] is None
    assert sensing.sensing_figures(tmp_path / "nothing", {}, t, X) == {}


def test_sensed_standin_flight_maps_the_forest_ahead(sim_binary, tmp_path):
    """End to end: the simulator's camera frames on the sensor bus reach mppid-mapper, whose
    maps name trees of the forest ahead; the hover stand-in answers (no obstacle is given)."""
    if paths.find_binary("mppid-mapper") is None:
        missing("mppid-mapper not built")
    from sitl_harness.fly import fly
    out = tmp_path / "sensed"
    score = fly(FlightSpec(scenario="forest_4m_sensed", seed=2, out=out, controller="standin", plots=False,
                           wall_timeout=180))
    stats = json.loads((out / "mapper_stats.json").read_text())
    assert stats["frames"] >= 30 and stats["maps"] >= 1 and stats["undecodable"] == 0
    s = score["sensing"]
    assert s["sensors"]["depth_camera"]["frames"] >= 30
    assert s["trees_sensed"] >= 1
    world = json.loads((out / "world.json").read_text())
    # Every tree sensed is one in the camera's view from the start (hovering at (0, 0, 2),
    # looking along +x: 87 deg, 10 m).
    first = sensing.first_sightings(world["obstacles"], sensing.read_sensed(out / "sensed.jsonl"), 0.25)
    for tree, f in zip(world["obstacles"], first):
        if f is not None:
            assert tree[0] > 0 and np.hypot(tree[0], tree[1]) - tree[2] < 10.5
            assert abs(np.degrees(np.arctan2(tree[1], tree[0]))) < 43.5 + 10


class _Rec:
    """What Scene logs, by entity (a stand-in for rerun's RecordingStream)."""

    def __init__(self):
        self.logged = {}

    def set_time(self, *_a, **_k):
        pass

    def log(self, path, obj):
        self.logged[path] = obj


def test_view_draws_the_occupied_cells_near_the_vehicle_and_the_sensor_frames():
    from mppi_lcm import local_map_t, point_cloud_t, vehicle_state_t
    from mppid_view.scene import Scene, cloud_world, occupied_cells
    m = local_map_t()
    m.nx, m.ny, m.nz, m.resolution, m.origin = 4, 4, 8, 0.5, [10.0, 0.0, 0.0]
    d = np.full((8, 4, 4), 1000, np.int16)
    d[4, 1, 2] = -100     # z 2.25, x 11.25, y 0.75: near the vehicle's altitude
    d[0, 0, 0] = 0        # z 0.25: far below it
    m.n_cells = d.size
    m.distance_mm = d.ravel().tolist()
    assert np.allclose(occupied_cells(m, 2.0), [[11.25, 0.75, 2.25]])
    assert len(occupied_cells(m, None)) == 2

    c = point_cloud_t()
    c.position, c.orientation = [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]  # yawed 180 deg
    c.n, c.x, c.y, c.z, c.hit = 2, [4.0, 10.0], [1.0, 0.0], [0.0, 0.0], [1, 0]
    o, p, hit = cloud_world(c)
    assert np.allclose(o, [1, 2, 3]) and np.allclose(p, [[-3.0, 1.0, 3.0], [-9.0, 2.0, 3.0]]) and list(hit) == [1, 0]

    rec = _Rec()
    scene = Scene(rec)
    s = vehicle_state_t()
    s.model, s.vehicle_count, s.nx, s.n, s.sample_utime = 1, 1, 16, 16, 1
    s.x = [0.0, 0.0, 2.0] + [0.0] * 13
    scene.log("MPPI_STATE", s)
    assert scene.log("MPPI_LOCAL_MAP", m) and scene.log("MPPI_DEPTH", c)
    assert len(rec.logged["world/map/occupied"].centers) == 1
    assert len(rec.logged["world/sensors/depth/points"].positions) == 1
    assert len(rec.logged["world/sensors/depth/rays"].strips) == 2
