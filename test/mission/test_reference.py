"""The mission tool's reference (mppi_mission/reference.py) against the closed-form values
that test/core/costs/test_reference.cpp checks on core's Reference: the two implement one spec."""
import math

import numpy as np
import pytest

from mppi_mission.reference import duration, evaluate

CIRCLE = {"kind": "circle", "center": [-5.0, 0.0, 2.0], "radius": 5.0, "speed": 3.0, "ramp": 3.0, "phase": 0.0}


def _angle(p):
    return math.atan2(p[1], p[0] + 5.0)


def test_a_circle_starts_at_rest_at_its_phase_and_reaches_its_speed_after_the_ramp():
    p, v, _ = evaluate(CIRCLE, [-1.0, 1.5, 3.0, 5.0])
    assert p[0][:2] == pytest.approx([0.0, 0.0], abs=1e-9) and not v[0].any()
    assert np.hypot(*v[1][:2]) == pytest.approx(1.5)
    assert _angle(p[2]) == pytest.approx(0.9) and np.hypot(*v[2][:2]) == pytest.approx(3.0)
    assert _angle(p[3]) == pytest.approx(2.1)


def test_the_phase_places_the_start():
    p, _, _ = evaluate({**CIRCLE, "ramp": 2.0, "phase": 1.0}, [0.0])
    assert p[0][:2] == pytest.approx([-5 + 5 * math.cos(1.0), 5 * math.sin(1.0)])


def test_without_a_ramp_the_curve_runs_at_any_time():
    t = np.array([-2.0, 0.0, 1.3, 8.0])
    p, _, _ = evaluate({**CIRCLE, "ramp": 0.0}, t)
    assert p[:, 0] == pytest.approx(-5 + 5 * np.cos(0.6 * t))
    assert p[:, 1] == pytest.approx(5 * np.sin(0.6 * t))


def test_a_line_ramps_up_cruises_ramps_down_and_stops_at_its_end():
    line = {"kind": "line", "center": [0.0, 0.0, 2.0], "end": [10.0, 0.0, 2.0], "speed": 2.0, "ramp": 2.0}
    p, v, _ = evaluate(line, [-0.5, 1.0, 3.5, 6.0, 9.0])
    assert p[:, 0] == pytest.approx([0.0, 0.5, 5.0, 9.5, 10.0])
    assert v[:, 0] == pytest.approx([0.0, 1.0, 2.0, 1.0, 0.0])
    assert duration(line) == pytest.approx(7.0)
    short = {**line, "end": [2.0, 0.0, 2.0], "speed": 4.0}
    p, v, _ = evaluate(short, [2.0, 4.0])
    assert p[:, 0] == pytest.approx([1.0, 2.0]) and v[:, 0] == pytest.approx([1.0, 0.0])


@pytest.mark.parametrize("kind", ["circle", "figure_eight", "line"])
def test_velocity_and_acceleration_are_the_derivatives(kind):
    ref = {**CIRCLE, "kind": kind, "ramp": 1.5, "phase": 0.7, "end": [6.0, 3.0, 1.0], "end_s": 6.0}
    t = np.array([0.4, 1.2, 3.3, 5.1, 5.9])
    h = 1e-5
    p, v, a = evaluate(ref, t)
    p1, v1, _ = evaluate(ref, t - h)
    p2, v2, _ = evaluate(ref, t + h)
    assert v == pytest.approx((p2 - p1) / (2 * h), abs=1e-6)
    assert a == pytest.approx((v2 - v1) / (2 * h), abs=1e-5)


def test_a_curve_with_an_end_ramps_down_to_rest_where_its_laps_end():
    ref = {**CIRCLE, "end_s": duration(CIRCLE, laps=2)}
    assert ref["end_s"] == pytest.approx(2 * 2 * math.pi * 5 / 3 + 3.0)  # the ramps lose ramp/2 each
    p, v, _ = evaluate(ref, [ref["end_s"] - 1.5, ref["end_s"], ref["end_s"] + 4.0])
    assert np.hypot(*v[0][:2]) == pytest.approx(1.5)
    assert p[1] == pytest.approx(p[2]) and not v[1:].any()
    assert p[1][:2] == pytest.approx([0.0, 0.0], abs=1e-9)  # two laps: back where it began
