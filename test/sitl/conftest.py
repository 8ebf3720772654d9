"""Fixtures of the SITL tests: the harness on the path, the binaries, result folders."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

from sitl_harness import paths  # noqa: E402

SITL = ROOT / "tools" / "sitl"


def sitl(*args, timeout=300, check=None):
    """Runs tools/sitl; returns the CompletedProcess."""
    p = subprocess.run([str(SITL), *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    if check is not None:
        assert p.returncode == check, f"rc={p.returncode}\nstdout:\n{p.stdout}\nstderr:\n{p.stderr}"
    return p


@pytest.fixture(scope="session")
def sim_binary():
    b = paths.find_binary("mppid-sim")
    if b is None:
        pytest.skip("mppid-sim not built (cmake --build <build> --target mppid-sim)")
    if paths.lcm_python_dir() is None:
        pytest.skip("mppi_lcm Python types not built (target mppi_lcm_python)")
    return b


@pytest.fixture(scope="session")
def mppid_binary(sim_binary):
    b = paths.find_binary("mppid")
    if b is None:
        pytest.skip("build/bin/mppid not built")
    return b


@pytest.fixture(scope="session")
def controller(sim_binary):
    """The real daemon when built, else the hover stand-in (for the cleanup tests)."""
    return "mppid" if paths.find_binary("mppid") else "standin"


def pid_alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            state = f.read().rsplit(")", 1)[1].split()[0]
        return state != "Z"
    except OSError:
        return False


def group_members(pgid: int) -> list[int]:
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    parts = f.read().rsplit(")", 1)[1].split()
                if int(parts[2]) == pgid and parts[0] != "Z":
                    out.append(int(d))
            except (OSError, ValueError, IndexError):
                pass
    return out
