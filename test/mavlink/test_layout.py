"""mppi_mavlink.layout against C++: each model's state and command names, in order, as the
enums of core/include/mppi/models/<model>.hpp declare them, and kNx/kNu."""
import re
from pathlib import Path

import pytest

from mppi_mavlink import layout

MODELS = Path(__file__).resolve().parents[2] / "core" / "include" / "mppi" / "models"


def header(model) -> tuple[list[tuple[str, ...]], int, int]:
    """The header's unnamed int enums (state first, then commands where named), kNx and kNu."""
    text = (MODELS / f"{model.NAME}.hpp").read_text()
    enums = [tuple(n.strip() for n in body.split(",") if n.strip())
             for body in re.findall(r"enum\s*:\s*int\s*\{([^}]*)\}", text)]
    nx = int(re.search(r"kNx\s*=\s*(\d+)", text).group(1))
    nu = int(re.search(r"kNu\s*=\s*(\d+)", text).group(1))
    return enums, nx, nu


@pytest.mark.parametrize("model", layout.MODELS, ids=lambda m: m.NAME)
def test_names_and_sizes_match_the_cpp_header(model):
    enums, nx, nu = header(model)
    assert enums and enums[0] == model.STATE, f"{model.NAME}.hpp's state enum"
    assert len(model.STATE) == nx and len(model.COMMAND) == nu
    if len(enums) > 1:
        assert enums[1] == model.COMMAND, f"{model.NAME}.hpp's command enum"


@pytest.mark.parametrize("model", layout.MODELS, ids=lambda m: m.NAME)
def test_each_name_is_its_index(model):
    for names in (model.STATE, model.COMMAND):
        assert [getattr(model, n) for n in names] == list(range(len(names)))


def test_quadrotor_rate_groups():
    Q = layout.QuadrotorRate
    x = list(Q.STATE)
    assert (x[Q.POS], x[Q.VEL], x[Q.QUAT], x[Q.RATES]) == (
        ["PX", "PY", "PZ"], ["VX", "VY", "VZ"], ["QW", "QX", "QY", "QZ"], ["WX", "WY", "WZ"])
    assert list(Q.COMMAND[Q.BODY_RATES]) == ["RATE_X", "RATE_Y", "RATE_Z"]
    assert list(layout.Quadrotor.STATE[layout.Quadrotor.MOTORS]) == ["M1", "M2", "M3", "M4"]
