"""The map to the autopilot through the stand-in autopilot: the bridge, with mppid not running and
the vehicle disarmed on the ground, sends a local map (published here as mppid-mapper would)
as OBSTACLE_DISTANCE at 15 per second of the autopilot's own clock (counted on the messages'
stamps, so a busy machine cannot fail it), with the trunk where it stands and "no obstacle"
elsewhere; OBSTACLE_DISTANCE_3D to ArduPilot only; nothing once the map goes stale, counted."""
import threading

import numpy as np
import pytest

from mavchain import Chain
from mavtest import LCM_URL, wait_for
from test_obstacle_distance import trunk_map

TRUNK = (4.0, 0.0, 0.3)          # 4 m east of the vehicle's start, 0.3 m radius: its face 3.7 m away
SETS = ["obstacle_distance.max_distance_m=7.0", "obstacle_distance.rate_hz=15"]
VEHICLE = {"px4": [], "ardupilot": ["GUID_OPTIONS=8", "MOT_THST_HOVER=0.4"]}


def publish_maps(stop: threading.Event, data: bytes):
    import lcm
    lc = lcm.LCM(LCM_URL)
    while not stop.wait(0.1):
        lc.publish("MPPI_LOCAL_MAP", data)


@pytest.mark.timeout(90)
@pytest.mark.parametrize("dialect", ["px4", "ardupilot"])
def test_the_map_reaches_the_autopilot_while_mppid_is_not_flying(netns, procs, tmp_path, dialect):
    c = Chain(procs, tmp_path, autopilot=dialect, mppid=False, vehicle_params=VEHICLE[dialect],
              bridge_sets=SETS).start()
    stop = threading.Event()
    pub = threading.Thread(target=publish_maps, args=(stop, trunk_map([TRUNK])), daemon=True)
    pub.start()
    try:
        wait_for(lambda: c.status().get("obstacle_distance_sent", 0) >= 50, 30, "3 s of OBSTACLE_DISTANCE")
    finally:
        stop.set()
        pub.join()
    st = c.status()
    # mppid not flying: never engaged (PX4's profile pre-streams, with nothing to stream), disarmed.
    assert st["engagement"] != "engaged" and not st["streaming"] and not st["armed"] and st["obstacle_maps"] >= 20
    # The map goes stale: ticks go on, counted, and nothing more is sent.
    stale0 = st["obstacle_stale"]
    st = wait_for(lambda: (s := c.status()).get("obstacle_stale", 0) >= stale0 + 10 and s, 20, "stale ticks")
    sent = st["obstacle_distance_sent"]
    wait_for(lambda: c.status().get("obstacle_stale", 0) >= st["obstacle_stale"] + 10, 20, "more stale ticks")
    assert c.status()["obstacle_distance_sent"] == sent
    summary = c.stop_vehicle()

    wire = c.wire()
    od = [r for r in wire if r["type"] == "OBSTACLE_DISTANCE"]
    od3 = [r for r in wire if r["type"] == "OBSTACLE_DISTANCE_3D"]
    assert len(od) == summary["counters"]["obstacle_distance"] == sent
    # Per second of the autopilot's clock (the messages' stamps are its time_usec): 15.
    stamps = np.array([r["time_usec"] for r in od]) // 1_000_000
    full = np.arange(stamps.min() + 1, stamps.max())      # the whole seconds in between
    per_second = [int(np.sum(stamps == s)) for s in full]
    print(f"{dialect}: OBSTACLE_DISTANCE per second of the autopilot's clock: {per_second}")
    assert len(full) >= 2 and min(per_second) >= 10, per_second
    assert all(abs(r["time_usec"] * 1e-6 - r["t"]) < 1.0 for r in od), "stamped with the autopilot's clock"
    for r in od:
        d = r["distances"]
        assert r["frame"] == 12 and r["increment_f"] == 5.0 and r["max_distance"] == 700
        assert 360 <= d[0] <= 375, d[:3] + d[-3:]                     # the trunk on the nose (east)
        others = [v for j, v in enumerate(d) if j not in (71, 0, 1)]
        assert others == [701] * len(others)
    if dialect == "ardupilot":
        assert od3 and len(od3) == summary["counters"]["obstacle_distance_3d"]
        assert {r["time_boot_ms"] for r in od3} <= {r["time_usec"] // 1000 for r in od}
        assert all(3.4 < r["x"] < 3.9 and abs(r["y"]) < 0.5 and r["frame"] == 12 for r in od3)
    else:
        assert not od3 and "obstacle_distance_3d" not in summary["counters"]
