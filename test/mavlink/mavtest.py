"""Fixtures and helpers for the MAVLink bridge tests (conftest.py re-exports the fixtures; a
uniquely named module, so test/sitl/conftest.py never shadows it).

Isolation: each test that needs the network runs in its own network namespace: the `netns`
fixture calls unshare(CLONE_NEWNET) on pytest's main thread (namespaces belong to threads;
the processes and threads it starts inherit it), brings `lo` up and routes 224.0.0.0/4 to
it, as tools/sitl_harness does with `unshare -n`. So the LCM bus
(udpm://239.255.76.67:7667?ttl=0) and the MAVLink UDP ports on 127.0.0.1 are private to
the test: nothing leaves the machine and parallel runs never mix. At the end the fixture
goes back to the namespace it came from.
"""
from __future__ import annotations

import ctypes
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from sitl_harness.logs import read_jsonl  # noqa: F401  (the tests read their flights' JSON lines through it)
from sitl_harness.turns import RealtimeTurn

ROOT = Path(__file__).resolve().parents[2]
# The bridge (mppi_mavlink) and the simulated autopilot (mavlink_vehicle) are the packages
# installed into the venv (tools/setup.sh); the tests' own modules are beside this file.
sys.path.insert(0, str(Path(__file__).resolve().parent))

LCM_URL = "udpm://239.255.76.67:7667?ttl=0"
CLONE_NEWNET = 0x40000000
PYTHON = sys.executable


def require_binary(name: str) -> Path:
    """A binary of the build, or the test fails saying so (tools/setup.sh builds them all)."""
    p = find_binary(name)
    assert p is not None, f"{name} not built: run tools/setup.sh (or set MPPID_BUILD_DIR)"
    return p


def find_binary(name: str) -> Path | None:
    dirs = [os.environ.get("MPPID_BUILD_DIR")] if os.environ.get("MPPID_BUILD_DIR") else []
    dirs += ["build", "build-mavlink", "build-sim", "build-daemon"]
    for d in dirs:
        p = (ROOT / d / "bin" / name)
        if p.is_file() and os.access(p, os.X_OK):
            return p
    return None


@pytest.fixture
def tap(request, netns):
    """A UDP tap between the bridge and the simulated autopilot (linktools.UdpTap) on the test
    module's TAP_PORT, keeping every datagram."""
    from linktools import UdpTap
    t = UdpTap(request.module.TAP_PORT, 14540)
    yield t
    t.close()


@pytest.fixture
def netns():
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    old = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    if libc.unshare(CLONE_NEWNET) != 0:
        os.close(old)
        pytest.fail(f"unshare(CLONE_NEWNET) failed (errno {ctypes.get_errno()}): these tests need root "
                    f"or CAP_SYS_ADMIN for a private network namespace")
    try:
        subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
        subprocess.run(["ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)
        yield
    finally:
        libc.setns(old, CLONE_NEWNET)
        os.close(old)


def _pdeathsig():
    try:
        ctypes.CDLL("libc.so.6").prctl(1, signal.SIGTERM)
    except OSError:
        pass


class Procs:
    """Processes of one test, each logging to <tmp>/<name>.log; all stopped at the end
    (SIGTERM, then SIGKILL after 3 s)."""

    def __init__(self, out: Path):
        self.out = out
        self.p: dict[str, subprocess.Popen] = {}
        self.turn = RealtimeTurn()  # held while a real-time mppid of this test flies (turns.py)

    def start(self, name, cmd, env_extra=None):
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"
        env.update(env_extra or {})
        log = open(self.out / f"{name}.log", "ab")
        self.p[name] = subprocess.Popen([str(c) for c in cmd], stdout=log, stderr=subprocess.STDOUT,
                                        stdin=subprocess.DEVNULL, cwd=ROOT, env=env, preexec_fn=_pdeathsig)
        log.close()
        return self.p[name]

    def stop(self, name, sig=signal.SIGTERM, timeout=3.0):
        p = self.p.get(name)
        if p is None or p.poll() is not None:
            return
        p.send_signal(sig)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5)

    def stop_all(self):
        for name in list(self.p)[::-1]:
            self.stop(name)
        self.turn.release()

    def log(self, name) -> str:
        f = self.out / f"{name}.log"
        return f.read_text(errors="replace") if f.exists() else ""


@pytest.fixture
def procs(tmp_path):
    pr = Procs(tmp_path)
    yield pr
    pr.stop_all()


def wait_for(pred, timeout, what, step=0.05):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(step)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def events(out: Path, name=None) -> list[dict]:
    ev = [r for r in read_jsonl(out / "truth.jsonl") if "event" in r]
    return [e for e in ev if name is None or e["event"] == name]


def finite(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)
