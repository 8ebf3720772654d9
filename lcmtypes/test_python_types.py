"""ctest lcm_types_python: the generated Python package imports and round-trips.

Usage: python test_python_types.py <build>/python
"""
import argparse
import sys

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("python_dir", metavar="PYTHON_DIR",
                    help="the build's generated Python package folder (<build>/python)")
sys.path.insert(0, parser.parse_args().python_dir)

import mppi_lcm  # noqa: E402

EXPECTED = {
    "command_t", "controller_status_t", "cylinder_t", "obstacles_t", "param_result_t",
    "param_update_t", "plan_t", "reference_t", "rollouts_t", "sim_clock_t", "vehicle_state_t",
}


def main() -> int:
    missing = sorted(t for t in EXPECTED if not hasattr(mppi_lcm, t))
    if missing:
        print(f"missing types: {missing}")
        return 1

    s = mppi_lcm.vehicle_state_t()
    s.utime, s.seq, s.sample_utime = 1_000_001, 7, 999_000
    s.model = mppi_lcm.vehicle_state_t.MODEL_QUADROTOR
    s.vehicle_count, s.nx = 2, 16
    s.n = s.vehicle_count * s.nx
    s.x = [0.5 * i for i in range(s.n)]
    d = mppi_lcm.vehicle_state_t.decode(s.encode())
    assert (d.utime, d.seq, d.sample_utime, d.model, d.n) == (1_000_001, 7, 999_000, 1, 32)
    assert list(d.x) == s.x

    o = mppi_lcm.obstacles_t()
    o.utime, o.seq, o.n = 5, 6, 2
    o.cylinders = []
    for i in range(o.n):
        c = mppi_lcm.cylinder_t()
        c.x, c.y, c.radius, c.vx, c.vy = float(i), 2.0, 0.25, 0.0, -1.0
        o.cylinders.append(c)
    d = mppi_lcm.obstacles_t.decode(o.encode())
    assert [c.x for c in d.cylinders] == [0.0, 1.0] and d.cylinders[1].vy == -1.0

    st = mppi_lcm.controller_status_t()
    st.backend, st.task = "cpu", "quadrotor_forest"
    d = mppi_lcm.controller_status_t.decode(st.encode())
    assert (d.backend, d.task) == ("cpu", "quadrotor_forest")

    try:
        mppi_lcm.command_t.decode(s.encode())
    except ValueError:
        pass
    else:
        raise AssertionError("decoding a vehicle_state_t as command_t must fail on the hash")

    print(f"{len(EXPECTED)} types ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
