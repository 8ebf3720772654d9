"""The other side of mppid-realsense in its test (test_realsense_driver.py): publishes the
vehicle's state (vehicle_state_t, the rate quadrotor's layout, standing still at a pose given on
the command line, sampled now on this host's clock) at 50 Hz, and keeps what it hears of the
driver's clouds; on SIGTERM writes them as JSON.

  python vehicle_feed.py STATE_URL CLOUD_URL OUT.json X Y Z YAW_DEG
"""
import json
import math
import signal
import sys
import threading
import time

import lcm
import mppi_lcm


def summary(m) -> dict:
    """What the test checks of one point_cloud_t."""
    pts = list(zip(m.x, m.y, m.z))
    r = [math.sqrt(x * x + y * y + z * z) for x, y, z in pts]
    hits = [p for p, h in zip(pts, m.hit) if h]
    return {"seq": m.seq, "n": m.n, "sensor": m.sensor, "utime": m.utime, "hits": len(hits),
            "finite": all(math.isfinite(v) for v in list(m.x) + list(m.y) + list(m.z)),
            "range_min": min(r), "range_max": max(r), "min_range": m.min_range, "max_range": m.max_range,
            "position": list(m.position), "orientation": list(m.orientation),
            "hit_x": [min(p[0] for p in hits), max(p[0] for p in hits)] if hits else None,
            "hit_y": [min(p[1] for p in hits), max(p[1] for p in hits)] if hits else None}


def main() -> None:
    state_url, cloud_url, out = sys.argv[1:4]
    x, y, z, yaw_deg = (float(v) for v in sys.argv[4:8])
    states = lcm.LCM(state_url)
    clouds_bus = lcm.LCM(cloud_url)
    clouds = []
    clouds_bus.subscribe("MPPI_DEPTH", lambda ch, data: clouds.append(summary(mppi_lcm.point_cloud_t.decode(data))))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    yaw = math.radians(yaw_deg)
    s = mppi_lcm.vehicle_state_t()
    s.model, s.vehicle_count, s.nx, s.n = s.MODEL_QUADROTOR_RATE, 1, 13, 13
    s.x = [x, y, z, 0.0, 0.0, 0.0, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2), 0.0, 0.0, 0.5]
    print(json.dumps({"event": "ready"}), flush=True)
    next_t = time.monotonic()
    while not stop.is_set():
        s.utime = s.sample_utime = time.time_ns() // 1000
        states.publish("MPPI_STATE", s.encode())
        s.seq += 1
        next_t += 0.02
        while not stop.is_set() and time.monotonic() < next_t:
            try:
                clouds_bus.handle_timeout(5)
            except OSError:  # interrupted by the signal
                break
    # What is on the bus still (the driver has exited): taken before the file is written.
    while clouds_bus.handle_timeout(50) > 0:
        pass
    with open(out, "w") as f:
        json.dump(clouds, f)


if __name__ == "__main__":
    main()
