"""The live 3D view (tools/view, docs/view.md) of a real-time forest flight with the rollout fan
on: a real headless browser (Debian's chromium, WebGL on SwiftShader) loads rerun's web viewer
while the flight flies and its screenshot shows the scene (the plan, the rollouts, the
obstacles, the trail: their colours counted, not just a non-blank page); a client of rerun's
gRPC protocol (rerun's own CLI) sees every entity and one message of each decodes; the
flight's LCM log converted to .rrd reads back with the LCM log's counts and values.

The view keeps up: its own report of the delay from each drawn state's publish on the bus to
its flush to the viewer's server is bounded (median, p95, max).

One flight serves every test (module fixture); the flight runs K = 1024 so it is light."""
from __future__ import annotations

import io
import json
import math
import os
import signal
import socket
import subprocess
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from sitl_helpers import ROOT, SITL, need_module
from sitl_harness import logs, paths

pytestmark = pytest.mark.timeout(240)

VIEW_WAIT_S = 20.0       # the view serves this long before the flight: the page loads (live: real time)
VIEW_READY_S = 90.0      # the view's servers up (rerun imports slowly on a loaded machine)
SCENE_SHOWN_S = 100.0    # the viewer's wasm compiled and the scene drawn (~20 s on an idle 2-core VM)
# The view's delay, bus -> viewer's server (docs/view.md, "Delay"). The median is the live
# bound; the state drawn is at most a state period (20 ms) old, so the tail above that is the
# scheduler's: the view runs at normal priority beside the SCHED_FIFO simulator and daemon and
# the browser's CPU renderer on a loaded 2-core machine (measured at load 20-23: max 0.14-0.94 s,
# the longest while the page loaded at the flight's start).
DELAY_MEDIAN_MS = 200.0
DELAY_P95_MS = 400.0
DELAY_MAX_MS = 2000.0
# The browser (a viewer's consumer, on a person's machine elsewhere) yields to the flight and the
# view here: its CPU renderer compiling and drawing would otherwise take the view's time.
BROWSER_NICENESS = 10
ENTITIES = ["/world/plan", "/world/rollouts/top", "/world/rollouts/random", "/world/obstacles",
            "/world/vehicles/0", "/world/vehicles/0/trail", "/world/goal", "/timing/compute_ms",
            "/timing/state_to_command_ms", "/timing/misses", "/optimizer/ess"]


def _free_view_port() -> int:
    """A web port P with P and P + 786 (the gRPC port tools/sitl derives) both free."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            p = s.getsockname()[1]
        if p + 786 > 65535:
            continue
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", p + 786))
                return p
            except OSError:
                continue
    raise RuntimeError("no free port pair")


def _wait_for(path: Path, text: str, timeout: float, proc: subprocess.Popen) -> str:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        body = path.read_text(errors="replace") if path.exists() else ""
        for line in body.splitlines():
            if text in line:
                return line
        if proc.poll() is not None:
            raise AssertionError(f"harness exited rc={proc.returncode} before '{text}':\n{body[-3000:]}")
        time.sleep(0.2)
    raise AssertionError(f"'{text}' not in {path} after {timeout:g} s")


def _seen(path: Path, text: str, proc: subprocess.Popen) -> bool:
    if path.exists() and text in path.read_text(errors="replace"):
        return True
    if proc.poll() is not None:
        raise AssertionError(f"harness exited rc={proc.returncode} before '{text}'")
    return False


def scene_pixels(png: bytes) -> dict[str, int]:
    """Pixels of each thing drawn, by colour, inside the 3D view (the left three quarters of
    the page, below the top bar)."""
    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int32)
    h, w, _ = img.shape
    v = img[40:h - 10, : int(0.74 * w)]
    r, g, b = v[..., 0], v[..., 1], v[..., 2]
    return {
        "plan": int(((r > 200) & (g < 80) & (b > 200)).sum()),                       # magenta
        "rollouts": int((((b > 170) & (r < 120) & (g > 60) & (g < 170))                  # low weight: blue
                         | ((r > 200) & (g > 50) & (g < 140) & (b < 60))).sum()),        # high weight: orange
        "obstacles": int(((g > r + 25) & (g > b + 25)).sum()),                            # shaded green
        "trail": int(((r < 70) & (g > 170) & (b > 170) & (abs(g - b) < 40)).sum()),    # cyan
        "colours": len(np.unique(v.reshape(-1, 3) // 8, axis=0)),
    }


def scene_shown(px: dict[str, int]) -> bool:
    return px["plan"] >= 15 and px["rollouts"] >= 40 and px["obstacles"] >= 200 and px["trail"] >= 10


def rrd_rows(path: Path) -> tuple[dict[str, int], dict[str, list], int]:
    """({entity: rows}, {entity: [record batches]}, blueprint stores) of a .rrd."""
    from rerun.chunk import RrdReader
    reader = RrdReader(path)
    rows: Counter = Counter()
    batches: dict[str, list] = {}
    for chunk in reader.stream():
        if chunk.is_static:
            continue
        rows[chunk.entity_path] += chunk.num_rows
        batches.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return dict(rows), batches, len(reader.blueprints())


def column(batches: list, name: str) -> list:
    """A component column's values over the entity's rows, in time order."""
    import pyarrow as pa
    table = pa.Table.from_batches(batches)
    table = table.sort_by("log_time")  # the order they were logged in
    return [x for x in table.column(name).to_pylist() if x is not None]


@pytest.fixture(scope="module")
def viewed_flight(mppid_binary, tmp_path_factory):
    need_module("rerun")
    need_module("websocket")
    if os.geteuid() != 0:
        if os.environ.get("CI"):
            pytest.fail("CI runs as root: the view test must run there")
        pytest.skip("the view joins the flight's network namespace with setns (root)")
    from mppid_view.browser import HeadlessChromium
    out = tmp_path_factory.mktemp("view") / "flight"
    port = _free_view_port()
    harness_log = out.parent / "harness.out"
    with open(harness_log, "wb") as hl:
        harness = subprocess.Popen(
            [str(SITL), "run", "--scenario", "forest_4m", "--seed", "3", "--out", str(out), "--view", "--view-port",
             str(port), "--view-hold", "200", "--no-plots", "--set", "mppi.rollouts=1024", "--realtime",
             "--view-wait", str(VIEW_WAIT_S)],
            stdout=hl, stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True)
    client = None
    result = {"out": out, "port": port}
    try:
        url = _wait_for(harness_log, "view: http", VIEW_READY_S, harness).split("view: ", 1)[1].strip()
        grpc = f"rerun+http://127.0.0.1:{port + 786}/proxy"
        # rerun's CLI as a client of the view's gRPC server: it saves what it receives.
        client = subprocess.Popen([str(paths.VENV_BIN / "rerun"), grpc, "--save", str(out.parent / "client.rrd")],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=out.parent,
                                  env={**os.environ, "RERUN_ANALYTICS": "0"}, start_new_session=True)
        t_load = time.monotonic()
        with HeadlessChromium(niceness=BROWSER_NICENESS) as browser:
            browser.open(url)  # the flight is flying: the page loads beside it
            # Pictures while it flies (the viewer shows its own latency figure when above 1 s).
            shots = 0
            while not _seen(harness_log, "view: serving", harness):  # until the flight is over
                if time.monotonic() - t_load > 180:
                    raise AssertionError("the flight did not end within 180 s")
                (out.parent / f"in_flight_{shots:02d}.png").write_bytes(browser.screenshot())
                shots += 1
                time.sleep(2.0)  # pacing the pictures, not a timing check
            deadline = t_load + SCENE_SHOWN_S
            png, px = b"", {}
            while time.monotonic() < deadline:
                png = browser.screenshot()
                px = scene_pixels(png)
                if scene_shown(px):
                    break
                time.sleep(2.0)
            result.update(png=png, pixels=px, load_s=time.monotonic() - t_load)
            (out.parent / "view.png").write_bytes(png)
        client.send_signal(signal.SIGINT)
        client.wait(timeout=30)
    finally:
        if client is not None and client.poll() is None:
            os.killpg(client.pid, signal.SIGKILL)
        if harness.poll() is None:
            os.killpg(harness.pid, signal.SIGTERM)  # the harness's group: it cleans up the flight and the view
        try:
            harness.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(harness.pid, signal.SIGKILL)
            harness.wait()
    result["harness"] = harness_log.read_text(errors="replace")
    result["view_log"] = (out / "view.log").read_text(errors="replace")
    return result


def view_delay(view_log: str) -> dict[str, float]:
    """The view's own report of its delay (tools/mppid_view/delay.py), its last line: from each
    drawn state's publish on the bus to the end of the flush to the viewer's server."""
    lines = [ln for ln in view_log.splitlines() if ln.startswith("view: delay bus -> viewer's server: draws=")]
    assert lines, f"the view reported no delay:\n{view_log[-2000:]}"
    return {k: float(v) for k, v in (f.split("=") for f in lines[-1].split(": ", 2)[2].split())}


def test_headless_browser_shows_the_scene(viewed_flight):
    px = viewed_flight["pixels"]
    assert scene_shown(px), (f"scene not drawn after {viewed_flight['load_s']:.0f} s: {px}; "
                             f"screenshot {viewed_flight['out'].parent / 'view.png'}")
    assert px["colours"] > 50, px


def test_view_keeps_up_with_the_bus(viewed_flight):
    """docs/view.md, "Delay": a real-time flight with the browser rendering on the CPU beside it;
    each drawn state reaches the viewer's server within the bounds."""
    d = view_delay(viewed_flight["view_log"])
    states = len(logs.read_lcm_log(viewed_flight["out"] / "flight.lcmlog", {"MPPI_STATE"})["MPPI_STATE"])
    # Draws at 10 Hz, the states at 50 Hz: one draw per five states, fewer when held up.
    assert states // 10 <= d["draws"] <= states, (d, states)
    assert d["median_ms"] < DELAY_MEDIAN_MS, d
    assert d["p95_ms"] < DELAY_P95_MS, d
    assert d["max_ms"] < DELAY_MAX_MS, d


def test_flight_with_the_view_publishes_rollouts(viewed_flight):
    # A real-time flight on a loaded machine: its success is the flight tests' (lock-step) to
    # assert; here it flew with the view and was scored.
    out = viewed_flight["out"]
    score = json.loads((out / "score.json").read_text())
    assert score["clock"] == "realtime" and score["sim_time"] > 2.0 and score["commands"] > 100, score
    msgs = logs.read_lcm_log(out / "flight.lcmlog", {"MPPI_ROLLOUTS", "MPPI_COMMAND"})
    fans = [m for _, m in msgs["MPPI_ROLLOUTS"]]
    commands = len(msgs["MPPI_COMMAND"])
    # 5 Hz of a 50 Hz loop: about one fan per ten commands.
    assert commands / 13 < len(fans) < commands / 7, (len(fans), commands)
    for m in fans:
        assert (m.count, m.top, m.vehicles, m.total) == (32, 16, 1, 1024)
        assert m.steps == 101 and m.npos == m.count * m.steps * 3
        assert all(math.isfinite(p) for p in m.pos)
        w = np.asarray(m.weight)
        assert np.all(w >= 0) and w.sum() <= 1.0 + 1e-4
        assert list(m.cost[: m.top]) == sorted(m.cost[: m.top])  # the top ones, lowest first
        assert w[0] == w.max()
    # The flight's .rrd, converted from the complete log after the flight.
    rows, _, blueprints = rrd_rows(out / "flight.rrd")
    assert rows["/timing/compute_ms"] == commands and rows["/world/rollouts/top"] == len(fans)
    assert blueprints >= 1


def test_protocol_client_sees_every_entity(viewed_flight):
    rows, batches, blueprints = rrd_rows(viewed_flight["out"].parent / "client.rrd")
    missing = [e for e in ENTITIES if rows.get(e, 0) == 0]
    assert not missing, (missing, sorted(rows))
    assert blueprints >= 1  # the layout came with the stream
    # One message of each decodes to what it should be.
    plan = column(batches["/world/plan"], "LineStrips3D:strips")[0][0]
    assert len(plan) == 101 and all(math.isfinite(c) for p in plan for c in p)
    top = column(batches["/world/rollouts/top"], "LineStrips3D:strips")[0]
    assert len(top) == 16 and all(len(s) == 101 for s in top)
    assert len(column(batches["/world/rollouts/random"], "LineStrips3D:strips")[0]) == 16
    assert len(column(batches["/world/obstacles"], "Cylinders3D:radii")[0]) > 5
    assert len(column(batches["/world/vehicles/0"], "Points3D:positions")[0]) == 1
    assert column(batches["/world/goal"], "Points3D:positions")[0][0][0] > 10  # the forest's goal, ahead
    for e in ("/timing/compute_ms", "/timing/state_to_command_ms", "/timing/misses", "/optimizer/ess"):
        v = column(batches[e], "Scalars:scalars")[0][0]
        assert math.isfinite(v) and v >= 0, (e, v)


def test_converted_log_matches_the_lcm_log(viewed_flight, tmp_path):
    out = viewed_flight["out"]
    rrd = tmp_path / "converted.rrd"
    p = subprocess.run([str(ROOT / "tools" / "view"), "convert", str(out / "flight.lcmlog"), str(rrd)],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stdout + p.stderr
    msgs = logs.read_lcm_log(out / "flight.lcmlog")
    rows, batches, blueprints = rrd_rows(rrd)
    assert blueprints >= 1
    count = {ch: len(v) for ch, v in msgs.items()}
    assert rows["/timing/compute_ms"] == count["MPPI_COMMAND"]
    assert rows["/timing/misses"] == count["MPPI_STATUS"]
    assert rows["/world/plan"] == count["MPPI_PLAN"]
    assert rows["/world/rollouts/top"] == count["MPPI_ROLLOUTS"]
    assert rows["/world/rollouts/random"] == count["MPPI_ROLLOUTS"]
    assert rows["/world/vehicles/0"] == count["MPPI_STATE"]
    assert rows["/world/obstacles"] == count["MPPI_OBSTACLES"]
    # Values: every command's compute time, and every fan's positions, in order.
    compute = [v[0] for v in column(batches["/timing/compute_ms"], "Scalars:scalars")]
    np.testing.assert_allclose(compute, [m.compute_us * 1e-3 for _, m in msgs["MPPI_COMMAND"]], rtol=1e-12)
    tops = column(batches["/world/rollouts/top"], "LineStrips3D:strips")
    for strips, (_, m) in zip(tops, msgs["MPPI_ROLLOUTS"]):
        xyz = np.asarray(m.pos, dtype=np.float32).reshape(m.count, m.steps, 3)[: m.top]
        np.testing.assert_array_equal(np.asarray(strips, dtype=np.float32), xyz)
    plans = column(batches["/world/plan"], "LineStrips3D:strips")
    first = msgs["MPPI_PLAN"][0][1]
    np.testing.assert_array_equal(np.asarray(plans[0][0], dtype=np.float32),
                                  np.asarray(first.pos, dtype=np.float32).reshape(-1, 3)[: first.horizon + 1])
