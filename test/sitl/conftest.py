"""Fixtures of the SITL tests: the binaries, the controller to fly."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

# The harness (sitl_harness) and the LCM types (mppi_lcm) are the packages installed into the
# venv by tools/setup.sh.
from sitl_harness import paths  # noqa: E402
from sitl_helpers import missing  # noqa: E402


@pytest.fixture(scope="session")
def sim_binary():
    b = paths.find_binary("mppid-sim")
    if b is None:
        missing("mppid-sim not built (cmake --build <build> --target mppid-sim)")
    if importlib.util.find_spec("mppi_lcm") is None:
        missing("mppi_lcm Python types not built (target mppi_lcm_python)")
    return b


@pytest.fixture(scope="session")
def mppid_binary(sim_binary):
    b = paths.find_binary("mppid")
    if b is None:
        missing("build/bin/mppid not built")
    return b


@pytest.fixture(scope="session")
def controller(sim_binary):
    """The real daemon when built, else the hover stand-in (for the cleanup tests)."""
    return "mppid" if paths.find_binary("mppid") else "standin"



