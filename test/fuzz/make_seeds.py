#!/usr/bin/env python3
"""Writes the seed corpus of the LCM fuzz targets (test/fuzz/corpus/<target>/): real encoded
messages, as the simulator, the bridge and an operator's lcm tools send them, each followed
by the one byte that picks the task (the index in mppi::task_names()). The fuzzer starts
from these; every seed gets past the fingerprint and into the validation and the loop.

    .venv/bin/python test/fuzz/make_seeds.py [--build build]

The YAML targets need no seeds here: their tests and tools/fuzz read config/tasks and
config/scenarios directly.
"""
import argparse
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT / "test" / "fuzz" / "corpus"

# mppi::task_names(): name, model id, states per vehicle, vehicles, controls per vehicle.
TASKS = [("cartpole_swingup", 3, 5, 1, 1), ("racecar_ellipse", 4, 9, 1, 2), ("quadrotor_forest", 1, 16, 1, 4),
         ("quadrotor_track", 1, 16, 1, 4), ("quadrotor_rate_forest", 2, 13, 1, 4),
         ("quadrotor_rate_track", 2, 13, 1, 4), ("team3_forest", 1, 16, 3, 4), ("team9_forest", 1, 16, 9, 4)]


def hover_state(model, nx, v):
    x = [0.0] * nx
    if model in (1, 2):
        x[0], x[1], x[2] = 0.5 * v, 2.0 * v, 2.0
        if model == 2:
            x[6] = 1.0                      # quaternion (w, x, y, z)
        else:
            x[12:16] = [4400.0] * 4          # motor speeds near hover, rpm
    elif model == 4:
        x[3] = 2.0                           # forward speed
    return x


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default="build")
    a = ap.parse_args()
    sys.path.insert(0, str(ROOT / a.build / "python"))
    import mppi_lcm as m

    def write(target, name, msg, task=None):
        d = CORPUS / target
        d.mkdir(parents=True, exist_ok=True)
        data = msg.encode() if hasattr(msg, "encode") else bytes(msg)
        if task is not None:
            data += bytes([task])
        (d / name).write_bytes(data)

    for ti, (task, model, nx, vehicles, nu) in enumerate(TASKS):
        # vehicle_state_t: a good one, then one per rejection the inbox knows.
        def state(seq=2, fill=None, n=None, model_=model, utime=1_000_000):
            s = m.vehicle_state_t()
            s.utime, s.seq, s.sample_utime, s.model = utime, seq, utime, model_
            s.vehicle_count, s.nx = vehicles, nx
            s.x = fill if fill is not None else sum((hover_state(model, nx, v) for v in range(vehicles)), [])
            s.n = len(s.x) if n is None else n
            return s
        good = state()
        write("fuzz_state", f"{task}_good", good, ti)
        nan = list(good.x)
        nan[len(nan) // 2] = math.nan
        write("fuzz_state", f"{task}_nan", state(fill=nan), ti)
        write("fuzz_state", f"{task}_duplicate", state(seq=1), ti)
        write("fuzz_state", f"{task}_wrong_model", state(model_=(model % 4) + 1), ti)
        write("fuzz_state", f"{task}_late", state(utime=1_500_000), ti)

        # reference_t of every kind.
        for kind, name in ((0, "hold"), (1, "circle"), (2, "figure_eight"), (3, "waypoint"), (4, "line")):
            r = m.reference_t()
            r.utime, r.seq, r.kind = 1_000_000, 1, kind
            r.center, r.radius, r.speed, r.yaw, r.t0_utime = [0.0, 0.0, 2.0], 5.0, 3.0, 0.0, 900_000
            r.ramp_s, r.phase, r.end_s = (2.0, 0.5, 20.0) if kind in (1, 2, 4) else (0.0, 0.0, 0.0)
            r.vehicle_count = vehicles if kind in (0, 3, 4) else 0
            r.goals = [[40.0, 2.0 * v, 2.0] for v in range(r.vehicle_count)]
            write("fuzz_reference", f"{task}_{name}", r, ti)

        # param_update_t: a tunable of each kind, a fixed one, an unknown one.
        for key, value in (("cost.w_obstacle", 2000.0), ("model.mass", 0.3), ("model.drag", 0.1),
                           ("cost.w_pos", 10.0), ("daemon.state_timeout_ms", 50.0),
                           ("daemon.failsafe_timeout_ms", 800.0), ("mppi.lambda", 2.0), ("no.such.key", 1.0)):
            p = m.param_update_t()
            p.utime, p.seq, p.key, p.value = 1_000_000, 1, key, value
            write("fuzz_params", f"{task}_{key}", p, ti)

        # sim_clock_t: on time with the state, and late.
        for name, sim_us in (("on_time", 1_000_000), ("late", 1_400_000), ("very_late", 3_000_000)):
            c = m.sim_clock_t()
            c.utime, c.seq, c.sim_utime, c.step = 1_000_000, 1, sim_us, 50
            write("fuzz_clock", f"{task}_{name}", c, ti)

        # command_t as the simulator gets it (one per plant kind).
        cmd = m.command_t()
        cmd.utime, cmd.seq, cmd.state_seq, cmd.mode = 1_000_000, 7, 6, 0
        cmd.kind = {1: 1, 2: 2}.get(model, 3)
        cmd.u = ([4400.0] * 4 if model == 1 else [9.81 * 0.25, 0.1, -0.1, 0.0] if model == 2 else [0.5] * nu) * vehicles
        cmd.n = len(cmd.u)
        write("fuzz_sim_command", f"{task}", cmd)

    # obstacles_t: a few, a moving one, and more than the 64 the loop keeps.
    for ti, (task, *_rest) in enumerate(TASKS):
        for name, count in (("few", 3), ("many", 100)):
            o = m.obstacles_t()
            o.utime, o.seq = 1_000_000, 1
            o.cylinders = []
            for i in range(count):
                c = m.cylinder_t()
                c.x, c.y, c.radius = 4.0 + 1.5 * (i % 20), -6.0 + 3.0 * (i // 20), 0.3
                c.vx, c.vy = (1.0, -0.5) if i == 1 else (0.0, 0.0)
                o.cylinders.append(c)
            o.n = count
            write("fuzz_obstacles", f"{task}_{name}", o, ti)
    print(f"seeds written under {CORPUS}")


if __name__ == "__main__":
    main()
