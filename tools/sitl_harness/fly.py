"""`sitl run`'s flight, start to end: fly it (its plant's class, flights/), convert the log
for the view, score it and plot it; and the process-level duties of a flight process
(stop signals, the parent watch)."""
from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

from .flights import flight_for
from .flights.base import FlightError, FlightSpec
from .turns import RealtimeTurn


def _write(path: Path, doc: dict) -> None:
    path.write_text(json.dumps(doc, indent=2))


def _convert_rrd(out: Path, info: dict) -> None:
    try:
        from mppid_view.convert import convert
        convert(out / "flight.lcmlog", out / "flight.rrd")
    except Exception as e:  # the rrd must never turn a flight into a crash
        info.setdefault("events", []).append(f"flight.rrd failed: {e!r}")


def fly(spec: FlightSpec) -> dict:
    """Runs one flight, scores it and plots it; returns the score (also in score.json)."""
    interrupt_on_stop_signals()
    out = Path(spec.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    try:
        flight = flight_for(spec)
    except FlightError as e:
        result = {"success": False, "reason": str(e), "harness_outcome": "error"}
        _write(out / "score.json", result)
        return result
    info = {}
    try:
        with RealtimeTurn():  # real time or lock-step: both hold the cores (turns.py)
            info = flight.run()
    except FlightError as e:
        info = {"harness_outcome": "error", "error": str(e)}
        _write(out / "harness.json", info)
    if spec.rrd or spec.view:
        _convert_rrd(out, info)
    result = flight.score(info)
    _write(out / "score.json", result)
    if spec.plots:
        try:
            flight.plot()
        except Exception as e:  # plots must never turn a flight into a crash
            result.setdefault("warnings", []).append(f"plots failed: {e!r}")
            _write(out / "score.json", result)
    return result


def _interrupt(*_):
    raise KeyboardInterrupt


def interrupt_on_stop_signals() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt in the main thread: a flight (a campaign, a
    study) stops, cleans up and leaves. SIGINT needs this too: Python installs its Ctrl-C
    handler only where SIGINT was not ignored at start, and a background job of a
    non-interactive shell (`tools/test.sh &`, a CI step, `nohup`) starts with it ignored. A
    campaign so started ignored an explicit SIGINT and flew on to its last flight (the cause
    of test_campaign_ctrl_c's 40 s time-outs "under load": the suite ran as a background job)."""
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _interrupt)


def watch_parent(parent_pid: int, interval: float = 0.2) -> None:
    """Ends this process like a SIGTERM (the flight is cleaned up) once the process that
    started it is gone: a campaign worker (a Ray worker, say) that dies mid-flight leaves no
    simulator or daemon behind. Watches the parent process itself (its pid changes to a
    reaper's when it dies), not the thread that started us, which PR_SET_PDEATHSIG would."""
    if os.getppid() != parent_pid:
        os.kill(os.getpid(), signal.SIGTERM)
        return

    def loop():
        while True:
            time.sleep(interval)
            if os.getppid() != parent_pid:
                os.kill(os.getpid(), signal.SIGTERM)
                return

    threading.Thread(target=loop, name="parent-watch", daemon=True).start()
