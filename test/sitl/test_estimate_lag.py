"""tools/sysid estimate-lag: how far the autopilot's estimate trails the truth (the vehicle
file's estimate_lag), on synthetic flights whose lag is known: a 5 m/s circle, the truth at
50 Hz as the referee writes it, the estimate `lag` behind it with a little noise, once in the
truth log's pairs (the estimator alone) and once as the states mppid flew on (an LCM log)."""
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
from sysid_fit import lag as lag_fit  # noqa: E402

WALL0, DELAY_US = 1_764_000_000_000_000, 800  # the host's clock at boot; the link's least delay


def circle(t):
    w = 5.0 / 5.0
    return (np.array([5 * math.cos(w * t), 5 * math.sin(w * t), 2.0]),
            np.array([-5 * w * math.sin(w * t), 5 * w * math.cos(w * t), 0.0]))


def write_flight(folder: Path, lag_s: float, seconds: float = 20.0, seed: int = 1) -> None:
    rng = np.random.default_rng(seed)
    rows, states = [], []
    for k in range(int(seconds * 50)):
        t = 10.0 + 0.02 * k
        x, v = circle(t)
        est = circle(t - lag_s)[0] + rng.normal(0, 0.01, 3)
        boot_us = int(t * 1e6)
        rows.append({"boot_us": boot_us, "paired": True, "wall_us": WALL0 + boot_us + DELAY_US + int(rng.uniform(0, 3000)),
                     "x": x.round(4).tolist(), "v": v.round(4).tolist(), "est": est.round(4).tolist()})
        states.append((WALL0 + boot_us + DELAY_US, est, v))
    (folder / "truth.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    import lcm
    from mppi_lcm import vehicle_state_t
    log = lcm.EventLog(str(folder / "flight.lcmlog"), "w", overwrite=True)
    for seq, (t_us, p, v) in enumerate(states, 1):
        m = vehicle_state_t()
        m.seq, m.utime, m.sample_utime = seq, t_us + 500, t_us
        m.model, m.vehicle_count, m.nx, m.n = vehicle_state_t.MODEL_QUADROTOR_RATE, 1, 13, 13
        m.x = list(p) + list(v) + [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        log.write_event(t_us + 500, "MPPI_STATE", m.encode())
    log.close()


@pytest.mark.parametrize("lag_ms", [0.0, 25.0, 60.0])
def test_the_lag_comes_out_of_the_flight(tmp_path, lag_ms):
    write_flight(tmp_path, lag_ms * 1e-3)
    r = lag_fit.estimate_lag(tmp_path)
    for key in ("estimator", "mppid_state"):
        assert r[key]["lag_s"] * 1e3 == pytest.approx(lag_ms, abs=1.5), (key, r[key])
        assert not r[key]["at_bound"]
        # a lag is an along-track error of -speed * lag, gone at the lag found
        assert r[key]["along_at_0_m"] == pytest.approx(-5.0 * lag_ms * 1e-3, abs=0.01)
        assert abs(r[key]["along_at_lag_m"]) < 0.01


def test_it_writes_the_vehicle_file_mppid_reads(tmp_path):
    write_flight(tmp_path, 0.025)
    out = tmp_path / "v.yaml"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "tools"), str(ROOT / "drivers" / "mavlink"),
                                                       os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-m", "sysid_fit", "estimate-lag", str(tmp_path), "--vehicle",
                        str(ROOT / "config" / "vehicles" / "arducopter_sitl.yaml"), "--out", str(out)],
                       capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0, r.stderr
    from mppi_mavlink import vehicle
    v = vehicle.load(out)
    assert v["estimate_lag"] == pytest.approx(0.025, abs=0.0015)
    assert v["rate_response"]["delay"] == pytest.approx(0.02)  # the rest is the prior's


def test_a_flight_at_rest_says_a_lag_needs_motion(tmp_path):
    rows = [{"boot_us": 10_000_000 + 20_000 * k, "paired": True, "wall_us": WALL0 + 10_000_000 + 20_000 * k,
             "x": [0, 0, 2], "v": [0, 0, 0], "est": [0, 0, 2]} for k in range(200)]
    (tmp_path / "truth.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    with pytest.raises(lag_fit.LagError, match="a lag needs motion"):
        lag_fit.estimate_lag(tmp_path / "truth.jsonl")
