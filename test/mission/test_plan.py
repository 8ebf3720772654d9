"""Mission files: a bad one is refused naming the field; legs become the steps the runner
flies (a curve starts at its point nearest the vehicle, reached along a line when far)."""
import math
from pathlib import Path

import numpy as np
import pytest

from mppi_mission import plan, reference

ROOT = Path(__file__).resolve().parents[2]


def _mission(*legs, **top):
    return plan.from_dict({"legs": list(legs), **top})


@pytest.mark.parametrize("doc, field", [
    ({"legs": []}, "legs"),
    ({"legs": [{"circle": {"center": [0, 0, 2], "radius": 5}}]}, "legs[0].circle.speed"),
    ({"legs": [{"circle": {"center": [0, 0], "radius": 5, "speed": 1}}]}, "legs[0].circle.center"),
    ({"legs": [{"hold": {"for": 3, "speeed": 1}}]}, "legs[0].hold.speeed"),
    ({"legs": [{"spiral": {}}]}, "legs[0]"),
    ({"legs": [{"hold": {}}], "takeof": 2}, "takeof"),
    ({"legs": [{"goal": {"radius": 1}}]}, "legs[0].goal.at"),
    ({"legs": [{"line": {"to": [1, 2, 3], "speed": -1}}]}, "legs[0].line.speed"),
    ({"legs": [{"hold": {}}], "obstacles": {"trees": [[1, 2]]}}, "obstacles.trees[0]"),
    ({"legs": [{"hold": {}}], "frame": "world"}, "frame"),
])
def test_a_bad_mission_names_the_field(doc, field):
    with pytest.raises(plan.PlanError) as e:
        plan.from_dict(doc)
    assert str(e.value).startswith(field), str(e.value)


def test_every_shipped_mission_loads_and_steps_through():
    files = sorted((ROOT / "config" / "missions").glob("*.yaml"))
    assert len(files) >= 6
    for f in files:
        m = plan.load(f)
        here = np.array([0.0, 0.0, 2.0])
        for i in range(len(m.legs)):
            steps = plan.steps(m, i, here, np.zeros(3))
            assert steps, f
            here = steps[-1].end


def test_a_circle_through_the_vehicle_starts_there_at_rest():
    m = _mission({"circle": {"center": [-5, 0, 2], "radius": 5, "speed": 3, "laps": 2}})
    (step,) = plan.steps(m, 0, [0.0, 0.0, 2.0], np.zeros(3))
    p, v, _ = reference.evaluate(step.ref, [0.0])
    assert p[0] == pytest.approx([0.0, 0.0, 2.0], abs=1e-9) and not v.any()
    assert step.ref["ramp"] == pytest.approx(3.0)  # speed / 1 m/s^2
    assert step.duration == step.ref["end_s"] == pytest.approx(2 * 2 * np.pi * 5 / 3 + 3.0)
    assert step.end == pytest.approx([0.0, 0.0, 2.0], abs=1e-9)  # at rest where it began


def test_a_curve_away_from_the_vehicle_is_reached_along_a_line_first():
    m = _mission({"circle": {"center": [10, 0, 2], "radius": 2, "speed": 4}})
    transit, curve = plan.steps(m, 0, [0.0, 0.0, 2.0], np.zeros(3))
    assert transit.transit and transit.kind == "line" and curve.kind == "circle"
    assert transit.ref["speed"] == 2.0  # TRANSIT_SPEED
    start = reference.evaluate(curve.ref, [0.0])[0][0]
    assert transit.end == pytest.approx(start) and start == pytest.approx([8.0, 0.0, 2.0])


def test_start_frame_offsets_x_y_but_not_z():
    m = _mission({"goal": {"at": [40, 0, 2]}}, frame="start")
    (step,) = plan.steps(m, 0, [3.0, 4.0, 2.5], np.array([3.0, 4.0, 0.0]))
    assert step.ref["center"] == [43.0, 4.0, 2.0]


def test_waypoints_are_lines_from_point_to_point():
    m = _mission({"waypoints": {"points": [[10, 0, 2], [10, 10, 2]], "speed": 2}})
    a, b = plan.steps(m, 0, [0.0, 0.0, 2.0], np.zeros(3))
    assert a.ref["center"] == [0.0, 0.0, 2.0] and a.ref["end"] == [10.0, 0.0, 2.0]
    assert b.ref["center"] == [10.0, 0.0, 2.0] and b.ref["end"] == [10.0, 10.0, 2.0]


def test_the_forest_is_seeded_and_clear_of_start_and_goal():
    m = plan.load(ROOT / "config" / "missions" / "rate_forest.yaml")
    a, b, c = m.trees((0.0, 0.0), 51), m.trees((0.0, 0.0), 51), m.trees((0.0, 0.0), 52)
    assert a == b and a != c and len(a) > 10
    assert min(np.hypot(x, y) - r for x, y, r in a) > 2.5
    assert min(np.hypot(x - 40, y) - r for x, y, r in a) > 2.5


FENCE = {"shape": "cylinder", "center": [0, 0], "radius": 8, "min_z": 0.5, "max_z": 5}


@pytest.mark.parametrize("legs, inside", [
    ([{"circle": {"center": [-3, 0, 2], "radius": 3, "speed": 2}}], True),
    ([{"circle": {"center": [-5, 0, 2], "radius": 5, "speed": 2}}], False),      # reaches x = -10
    ([{"line": {"to": [7, 0, 2], "speed": 1}}], True),
    ([{"line": {"to": [7.9, 0, 2], "speed": 1}}], False),                       # the vehicle's 0.2 m
    ([{"hold": {"for": 1}}, {"goal": {"at": [0, 0, 6]}}], False),               # above max_z
    ([{"waypoints": {"points": [[3, 3, 2], [3, -3, 2], [12, 0, 2]], "speed": 2}}], False)])
def test_every_leg_is_checked_against_the_fence_before_flight(legs, inside):
    doc = {"legs": legs, "takeoff": 2.0, "fence": FENCE}
    if inside:
        assert plan.from_dict(doc).fence.radius == 8
    else:
        with pytest.raises(plan.PlanError, match=r"^fence: legs\["):
            plan.from_dict(doc)


def test_a_bad_fence_names_the_field():
    with pytest.raises(plan.PlanError, match="fence.radius"):
        plan.from_dict({"legs": [{"hold": {}}], "fence": {"shape": "cylinder"}})


def _yaws(m, heading=0.3):
    here, out = np.array([0.0, 0.0, 2.0]), []
    for i in range(len(m.legs)):
        for st in plan.steps(m, i, here, np.zeros(3), heading):
            out.append(round(st.ref["yaw"], 6))
            heading, here = st.ref["yaw"], st.end
    return out


def test_yaw_holds_the_heading_at_the_hand_over_by_default():
    m = _mission({"hold": {"for": 1}}, {"line": {"to": [0, 5, 2], "speed": 1}},
                 {"circle": {"center": [0, 0, 2], "radius": 5, "speed": 2}})
    assert set(_yaws(m, 0.3)) == {0.3}       # no turn to face east at the hand-over


def test_yaw_in_degrees_and_along_the_path():
    m = _mission({"waypoints": {"points": [[0, 5, 2], [5, 5, 2]], "speed": 1}}, {"goal": {"at": [5, 0, 2]}},
                 {"hold": {"for": 1}}, {"circle": {"center": [0, 0, 2], "radius": 5, "speed": 2, "yaw": 45}},
                 yaw="path")
    north, east, south = round(math.pi / 2, 6), 0.0, round(-math.pi / 2, 6)
    ys = _yaws(m)
    # waypoints: north then east; the goal: south; the hold keeps it; the circle: its own 45 deg,
    # reached along a transit line that faces along it (path).
    assert ys[:4] == [north, east, south, south]
    assert ys[-1] == round(math.radians(45), 6)


@pytest.mark.parametrize("doc, field", [
    ({"legs": [{"circle": {"center": [0, 0, 2], "radius": 5, "speed": 2}}], "yaw": "path"}, "legs[0].circle.yaw"),
    ({"legs": [{"hold": {"yaw": "north"}}]}, "legs[0].hold.yaw"),
    ({"legs": [{"hold": {}}], "yaw": 400}, "yaw")])
def test_a_bad_yaw_names_the_field(doc, field):
    with pytest.raises(plan.PlanError) as e:
        plan.from_dict(doc)
    assert str(e.value).startswith(field), str(e.value)
