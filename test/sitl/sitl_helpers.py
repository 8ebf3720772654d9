"""Helpers of the SITL tests (a unique module name: test/ may hold other conftest.py files)."""
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


def missing(why: str):
    """Skip with the reason on a developer's partial build; in CI (CI set), where
    tools/setup.sh builds everything, a missing piece is a failure, never a silent skip."""
    if os.environ.get("CI"):
        pytest.fail(why + " (CI builds everything: this is a build problem)")
    pytest.skip(why)


def sitl(*args, timeout=300, check=None):
    """Runs tools/sitl; returns the CompletedProcess."""
    p = subprocess.run([str(SITL), *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    if check is not None:
        assert p.returncode == check, f"rc={p.returncode}\nstdout:\n{p.stdout}\nstderr:\n{p.stderr}"
    return p


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


def write_scenario(path: Path, name: str | None = "hold_short", duration: float = 1.0, base: str = "hold") -> Path:
    """A short test scenario file. base "hold": the 16-state quadrotor told to hold its
    start (the hover stand-in succeeds); "rate_circle": rate_track_circle, shortened."""
    import yaml

    if base == "hold":
        doc = {"description": "test: hold the start", "task": "quadrotor_track",
               "plant": {"model": "quadrotor", "params": {}},
               "timing": {"physics_hz": 1000, "state_hz": 50, "duration": duration},
               "world": {"start": [3, 0, 2], "stop_at_goal": False},
               "reference": {"kind": "hold", "center": [3, 0, 2], "yaw": 0.0},
               "success": {"type": "tracking", "max_rmse": 0.3, "settle": 0.0}}
    else:
        doc = yaml.safe_load((ROOT / "config" / "scenarios" / "rate_track_circle.yaml").read_text())
        doc["timing"]["duration"] = duration
        doc["success"]["settle"] = min(1.0, duration / 2)
    doc.pop("name", None)
    if name:
        doc = {"name": name, **doc}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def scenario_runs(out: Path) -> dict:
    from sitl_harness.results import load_campaign

    return load_campaign(out).by_key()


def need_module(name: str):
    """A PyPI package of requirements.txt: skipped with the reason on a partial venv; in CI
    (CI set, tools/setup.sh installs requirements.txt) a failure, never a silent skip."""
    try:
        return __import__(name)
    except ImportError:
        why = f"Python package {name} not installed (pip install -r requirements.txt)"
        if os.environ.get("CI"):
            pytest.fail(why)
        pytest.skip(why)


def fake_ardupilot(tmp_path: Path) -> Path:
    """An ArduPilot checkout's layout: the SITL binary and the copter defaults beside it."""
    ap = tmp_path / "ardupilot"
    (ap / "Tools" / "autotest" / "default_params").mkdir(parents=True)
    (ap / "Tools" / "autotest" / "default_params" / "copter.parm").write_text("FRAME_CLASS 1\n")
    binary = ap / "build" / "sitl" / "bin" / "arducopter"
    binary.parent.mkdir(parents=True)
    binary.write_text("#!/bin/sh\nexit 0\n")
    binary.chmod(0o755)
    return binary
