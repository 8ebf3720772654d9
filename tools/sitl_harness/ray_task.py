"""One flight as a Ray task. Standard library only (and Ray, inside a worker): the module is
shipped by value, so a worker needs no copy of the harness on its Python path, only the
repository (built, its Python packages installed into .venv) at the same path as on the
driver.

The flight runs as its own `sitl run` process in its own session: its own network
namespace and LCM URL (sandbox.py), a parent watch (`--parent-pid`) that stops and cleans
up the flight when this worker dies, and, when Ray cancels the task, a SIGTERM that does
the same."""
from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import tarfile
from pathlib import Path


def _prepare(payload: dict, out: Path) -> list[str]:
    """Clears the folder of a previous attempt; `sitl run`'s arguments for this node."""
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
    return args


def _node_id():
    try:
        import ray

        return ray.get_runtime_context().get_node_id()
    except Exception:  # noqa: BLE001 - called outside Ray (tests)
        return None


def _fly(root: Path, out: Path, args: list[str]) -> int:
    """`sitl run` in its own session; on cancellation (Ray raises KeyboardInterrupt here) or
    failure, SIGTERM (the flight cleans up), SIGKILL to its session after a grace period."""
    python = root / ".venv" / "bin" / "python"
    python = str(python) if python.is_file() else sys.executable
    cmd = [python, "-m", "sitl_harness", "run", *args, "--parent-pid", str(os.getpid())]
    with open(out / "harness.stderr", "wb") as err:
        p = subprocess.Popen(cmd, cwd=str(root), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=err, start_new_session=True)
    try:
        return p.wait()
    except BaseException:
        try:
            p.send_signal(signal.SIGTERM)
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        except ProcessLookupError:
            pass
        raise


def _tar(folder: Path) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        tar.add(str(folder), arcname=".")
    return buf.getvalue()


def run_flight_task(payload: dict) -> dict:
    root = Path(payload["root"])
    out = Path(payload["out"])
    args = _prepare(payload, out)
    node_id = _node_id()
    (out / "worker.json").write_text(json.dumps({"pid": os.getpid(), "node_id": node_id,
                                                 "attempt": payload.get("attempt", 1),
                                                 "worker_niceness": os.getpriority(os.PRIO_PROCESS, 0)}))
    rc = _fly(root, out, args)
    try:
        score = json.loads((out / "score.json").read_text())
    except (OSError, ValueError):
        score = None
    files = None
    if payload.get("driver_node_id") and node_id and node_id != payload["driver_node_id"]:
        files = _tar(out)  # another machine: bring the result folder back to the driver
    return {"rc": rc, "score": score, "files": files, "node_id": node_id, "pid": os.getpid()}
