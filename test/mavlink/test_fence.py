"""The geofence (mppi_mavlink/fence.py) from tables: what each shape lets in, the margin, and
the files it refuses, naming the field."""
import math

import pytest

from mppi_mavlink import fence, settings

CYL = fence.parse({"shape": "cylinder", "center": [1.0, -1.0], "radius": 5.0, "min_z": 0.5, "max_z": 10.0})
BOX = fence.parse({"shape": "box", "min": [-2.0, -3.0], "max": [20.0, 3.0], "max_z": 4.0})


@pytest.mark.parametrize("f,p,margin,inside", [
    (CYL, (1, -1, 2), 0, True), (CYL, (5.9, -1, 2), 0, True), (CYL, (6.1, -1, 2), 0, False),
    (CYL, (5.9, -1, 2), 0.2, False), (CYL, (1, -1, 10.5), 0, False), (CYL, (1, -1, 0.4), 0, False),
    (CYL, (1, -1, 9.9), 0.2, False), (CYL, (math.nan, 0, 2), 0, False),
    (BOX, (0, 0, 1), 0, True), (BOX, (19.9, 2.9, 1), 0, True), (BOX, (20.1, 0, 1), 0, False),
    (BOX, (0, -3.1, 1), 0, False), (BOX, (0, 0, -50), 0, True), (BOX, (0, 0, 4.1), 0, False),
    (BOX, (19.9, 0, 1), 0.5, False)])
def test_breach(f, p, margin, inside):
    assert (f.breach(p, margin) == "") == inside


@pytest.mark.parametrize("doc,field", [
    ({"shape": "sphere"}, "shape"), ({"shape": "cylinder"}, "radius"), ({"shape": "cylinder", "radius": -1}, "radius"),
    ({"shape": "box", "min": [0, 0], "max": [0, 5]}, "min must be below"), ({"shape": "box", "min": [0, 0]}, "max"),
    ({"shape": "cylinder", "radius": 5, "min_z": 3, "max_z": 2}, "min_z"), ({"radius": 5, "colour": 1}, "fence"),
    ({"shape": "cylinder", "radius": 5, "center": [0, "x"]}, "center")])
def test_refused(doc, field):
    with pytest.raises(fence.FenceError, match=field):
        fence.parse(doc)


def test_none_and_settings():
    assert fence.parse(None) is None and fence.parse({}) is None
    s = settings.load(None, ["fence.shape=cylinder", "fence.radius=30", "fence.max_z=20"])
    assert s["fence"]["radius"] == 30
    with pytest.raises(settings.SettingsError, match="fence.radius"):
        settings.load(None, ["fence.shape=cylinder"])
