"""The command lines of mppid-sim, mppid-sensors and mppid-mapper (CLI11, drivers/cli): --help
lists every option the harness and the scripts pass and exits 0; a bad option or value exits 2
naming it, before anything runs."""
from __future__ import annotations

import json
import signal
import subprocess
import time

import pytest

from conftest import missing
from sitl_harness import paths

# Every option each program takes (the harness, tools/ and the deploy files pass these).
OPTIONS = {
    "mppid-sim": ["--scenario", "--seed", "--lockstep", "--realtime", "--ideal", "--latency", "--lcm-url",
                  "--sensor-lcm-url", "--out", "--channel-prefix", "--duration", "--quiet"],
    "mppid-sensors": ["--sensing", "--seed", "--lcm-url", "--sensor-lcm-url", "--tree-height", "--max-truth-age",
                      "--stats"],
    "mppid-mapper": ["--config", "--set", "--lcm-url", "--sensor-lcm-url", "--channel-prefix", "--stats",
                     "--sensed"],
}

SCENARIO = str(paths.scenario_path("forest_3m"))
SENSING = str(paths.MISSIONS / "rate_forest_sensed.yaml")

# (program, arguments, what the error must name)
BAD = [
    ("mppid-sim", [], "--scenario"),
    ("mppid-sim", ["--scenario", SCENARIO, "--seed", "seven"], "--seed"),
    ("mppid-sim", ["--scenario", SCENARIO, "--duration", "2s"], "--duration"),
    ("mppid-sim", ["--scenario", SCENARIO, "--latency", "10"], "--latency"),
    ("mppid-sim", ["--scenario", SCENARIO, "--latency", "soon"], "--latency"),
    ("mppid-sim", ["--scenario", SCENARIO, "--lockstep", "--realtime"], "--lockstep"),
    ("mppid-sim", ["--scenario", SCENARIO, "--lockstep", "--ideal", "--latency", "0.01"], "--ideal"),
    ("mppid-sim", ["--scenario", SCENARIO, "--speed", "2"], "--speed"),
    ("mppid-sim", ["--scenario"], "--scenario"),
    ("mppid-sensors", [], "--sensing"),
    ("mppid-sensors", ["--sensing", SENSING, "--tree-height", "0"], "--tree-height"),
    ("mppid-sensors", ["--sensing", SENSING, "--max-truth-age", "x"], "--max-truth-age"),
    ("mppid-sensors", ["--sensing", SENSING, "--seed", "-1x"], "--seed"),
    ("mppid-sensors", ["--sensing", SENSING, "stray"], "stray"),
    ("mppid-mapper", ["--rate", "20"], "--rate"),
    ("mppid-mapper", ["--stats"], "--stats"),
]


def binary(name: str):
    b = paths.find_binary(name)
    if b is None:
        missing(f"{name} not built (cmake --build <build> --target {name})")
    return b


@pytest.mark.parametrize("program", sorted(OPTIONS))
def test_help_lists_every_option_and_exits_0(program):
    p = subprocess.run([str(binary(program)), "--help"], capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith(program + ": ") and f"Usage: {program} " in p.stdout, p.stdout
    for option in OPTIONS[program] + ["--help"]:
        assert option in p.stdout, f"{program} --help does not list {option}:\n{p.stdout}"


@pytest.mark.parametrize("program, args, named", BAD, ids=[f"{b[0]}:{' '.join(b[1][-2:])}" for b in BAD])
def test_a_bad_option_or_value_exits_2_naming_it(program, args, named, tmp_path):
    p = subprocess.run([str(binary(program))] + args, capture_output=True, text=True, timeout=30, cwd=tmp_path)
    assert p.returncode == 2, (p.returncode, p.stderr)
    assert p.stderr.startswith(program + ": ") and named in p.stderr, p.stderr
    assert not list(tmp_path.iterdir())  # nothing ran: no world.json, no stats


def test_the_simulator_takes_the_harness_options_and_stops_on_sigterm(sim_binary, tmp_path):
    """What tools/sitl_harness/flights/sim.py passes for a lock-step flight with a fixed latency
    charge (and --channel-prefix) is taken; no controller answers, so it waits for the first
    command until SIGTERM, which ends the run as interrupted (exit 4) with its logs written."""
    p = subprocess.Popen([str(sim_binary), "--scenario", SCENARIO, "--seed", "51", "--lcm-url", "memq://", "--out",
                          str(tmp_path), "--lockstep", "--latency", "0.01", "--channel-prefix", "T_",
                          "--sensor-lcm-url", "memq://", "--quiet"], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not (tmp_path / "truth.jsonl").exists() and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        world = json.loads((tmp_path / "world.json").read_text())
        p.send_signal(signal.SIGTERM)
        err = p.communicate(timeout=30)[1]
    finally:
        p.kill()
    assert world["lockstep"] is True and world["latency_charge"] == 0.01 and world["seed"] == 51
    assert p.returncode == 4, err
    assert json.loads((tmp_path / "sim_summary.json").read_text())["outcome"] == "interrupted"
