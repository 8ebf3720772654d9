"""Nothing is left running when a flight goes wrong."""
from __future__ import annotations

import json
import signal
import subprocess
import time

from sitl_helpers import ROOT, SITL, group_members, pid_alive, sitl


def _assert_all_gone(out):
    pids = json.loads((out / "pids.json").read_text())
    for name, pid in pids.items():
        if name != "pgid":
            assert not pid_alive(pid), f"{name} (pid {pid}) still running"
    left = group_members(pids["pgid"])
    assert left == [], [open(f"/proc/{p}/cmdline").read().replace("\0", " ") for p in left]


def test_controller_killed_mid_flight(controller, tmp_path):
    out = tmp_path / "killed"
    t0 = time.monotonic()
    # In real time: in lock-step the flight may end before the kill (the stand-in answers at
    # once; mppid on the SIMD CPU backend flies the 4 m forest in ~1.2 s of wall time).
    p = sitl("run", "--scenario", "forest_4m", "--controller", controller, "--out", out,
             "--kill-controller-after", 2.0, "--timeout", 120, "--realtime", timeout=180)
    assert p.returncode == 1, p.stderr
    score = json.loads((out / "score.json").read_text())
    assert score["success"] is False
    assert "controller" in score["reason"]
    _assert_all_gone(out)
    assert time.monotonic() - t0 < 60  # noticed at once, not at a timeout


def test_harness_sigterm_mid_flight(controller, tmp_path):
    """SIGTERM (or Ctrl-C) to the harness: the flight is stopped and cleaned up."""
    out = tmp_path / "term"
    p = subprocess.Popen([str(SITL), "run", "--scenario", "forest_4m", "--controller", controller, "--out", str(out),
                          "--realtime"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 30
    while not (out / "pids.json").is_file() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert (out / "pids.json").is_file()
    time.sleep(1.0)
    p.send_signal(signal.SIGTERM)
    p.wait(timeout=30)
    assert p.returncode != 0
    _assert_all_gone(out)


def test_campaign_ctrl_c(tmp_path):
    """Ctrl-C on a campaign stops its running flights at once, each cleaned up."""
    from sitl_harness import paths
    if paths.find_binary("mppid-sim") is None:
        from conftest import missing
        missing("mppid-sim not built")
    out = tmp_path / "camp"
    # Started as a background job of a non-interactive shell starts it (`tools/test.sh &`, a
    # CI step): with SIGINT ignored. The campaign must stop on it all the same.
    p = subprocess.Popen([str(SITL), "campaign", "--scenarios", "forest_4m", "--seeds", "4", "--out", str(out),
                          "--controller", "standin", "--realtime"], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    pid_files = lambda: list(out.glob("forest_4m/seed_*/pids.json"))
    deadline = time.monotonic() + 30
    while not pid_files() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert pid_files()
    time.sleep(1.0)
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    p.wait(timeout=40)
    assert time.monotonic() - t0 < 20  # not after the remaining flights
    assert p.returncode == 130
    for f in pid_files():
        _assert_all_gone(f.parent)


def test_a_namespace_that_cannot_be_set_up_is_a_clear_error(tmp_path):
    """No `ip` to bring up lo in the flight's namespace: the flight fails saying so (it once
    failed again in its clean-up, on a process group that never existed)."""
    import os
    import shutil
    tools = tmp_path / "bin"
    tools.mkdir()
    for t in ("sh", "dirname", "unshare"):
        (tools / t).symlink_to(shutil.which(t))
    env = dict(os.environ, PATH=str(tools))
    p = subprocess.run([str(SITL), "run", "--scenario", "forest_4m", "--seed", "1", "--out", str(tmp_path / "o")],
                       env=env, capture_output=True, text=True, timeout=60)
    assert p.returncode == 1, p.stderr
    assert "Traceback" not in p.stderr, p.stderr
    score = json.loads((tmp_path / "o" / "score.json").read_text())
    assert score["success"] is False
    assert "network namespace set-up failed" in score["reason"] and "ip: not found" in score["reason"], score
