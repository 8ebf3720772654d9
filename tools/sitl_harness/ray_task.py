"""One flight as a Ray task. Standard library only (and Ray, inside a worker): the function
is shipped by value, so a worker needs no copy of the harness on its Python path, only the
repository (built) at the same path as on the driver.

The flight runs as its own `sitl run` process in its own session: its own network
namespace and LCM URL (flight.py), a parent watch (`--parent-pid`) that stops and cleans
up the flight when this worker dies, and, when Ray cancels the task, a SIGTERM that does
the same."""
from __future__ import annotations


def run_flight_task(payload: dict) -> dict:
    import io
    import json
    import os
    import signal
    import subprocess
    import sys
    import tarfile
    from pathlib import Path

    root = Path(payload["root"])
    out = Path(payload["out"])
    python = root / ".venv" / "bin" / "python"
    python = str(python) if python.is_file() else sys.executable
    args = list(payload["args"])
    out.mkdir(parents=True, exist_ok=True)
    for stale in ("score.json", "pids.json", "harness.json"):
        try:
            (out / stale).unlink()
        except FileNotFoundError:
            pass
    # A scenario file the driver named may not exist on this node: fly its text.
    scen = payload.get("scenario_file")
    if scen and not Path(scen).is_file():
        local = out / "scenario.yaml"
        local.write_text(payload["scenario_text"])
        args[args.index(scen)] = str(local)
    node_id = None
    try:
        import ray

        node_id = ray.get_runtime_context().get_node_id()
    except Exception:  # noqa: BLE001 - called outside Ray (tests)
        pass
    (out / "worker.json").write_text(json.dumps({"pid": os.getpid(), "node_id": node_id,
                                                 "attempt": payload.get("attempt", 1),
                                                 "worker_niceness": os.getpriority(os.PRIO_PROCESS, 0)}))
    env = dict(os.environ)
    env["PYTHONPATH"] = str(root / "tools")
    cmd = [python, "-m", "sitl_harness", "run", *args, "--parent-pid", str(os.getpid())]
    with open(out / "harness.stderr", "wb") as err:
        p = subprocess.Popen(cmd, cwd=str(root), env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=err, start_new_session=True)
    try:
        rc = p.wait()
    except BaseException:
        # Cancelled (Ray raises KeyboardInterrupt here) or failing: the flight cleans up on
        # SIGTERM; SIGKILL to its session if it does not within the grace period.
        try:
            p.send_signal(signal.SIGTERM)
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        except ProcessLookupError:
            pass
        raise
    try:
        score = json.loads((out / "score.json").read_text())
    except (OSError, ValueError):
        score = None
    files = None
    if payload.get("driver_node_id") and node_id and node_id != payload["driver_node_id"]:
        # Another machine: bring the result folder back to the driver.
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w:gz") as tar:
            tar.add(str(out), arcname=".")
        files = buf.getvalue()
    return {"rc": rc, "score": score, "files": files, "node_id": node_id, "pid": os.getpid()}
