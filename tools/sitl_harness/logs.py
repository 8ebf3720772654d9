"""Reading a flight's records: the LCM log (decoded), the simulator's truth log."""
from __future__ import annotations

import json
from pathlib import Path


def read_lcm_log(path: Path, channels=None) -> dict[str, list]:
    """{channel: [(receive_utime, decoded message), ...]} for the mppi_lcm channels."""
    import lcm
    from mppi_lcm import (command_t, controller_status_t, obstacles_t, param_result_t, param_update_t, plan_t,
                          reference_t, rollouts_t, sim_clock_t, vehicle_state_t)

    types = {"MPPI_COMMAND": command_t, "MPPI_STATE": vehicle_state_t, "MPPI_STATUS": controller_status_t,
             "MPPI_PLAN": plan_t, "MPPI_REFERENCE": reference_t, "MPPI_OBSTACLES": obstacles_t,
             "MPPI_SIM_CLOCK": sim_clock_t, "MPPI_PARAMS": param_update_t, "MPPI_PARAM_RESULT": param_result_t,
             "MPPI_ROLLOUTS": rollouts_t}
    out: dict[str, list] = {}
    if not Path(path).is_file():
        return out
    log = lcm.EventLog(str(path), "r")
    for ev in log:
        t = types.get(ev.channel)
        if t is None or (channels and ev.channel not in channels):
            continue
        try:
            msg = t.decode(ev.data)
        except ValueError:
            continue
        out.setdefault(ev.channel, []).append((ev.timestamp, msg))
    log.close()
    return out


def command_payloads(path: Path) -> list[tuple]:
    """The commands of a log, decoded, without their utime: what a deterministic lock-step
    run must reproduce exactly."""
    cmds = read_lcm_log(path, {"MPPI_COMMAND"}).get("MPPI_COMMAND", [])
    return [(m.seq, m.state_seq, m.mode, m.kind, m.n, tuple(m.u)) for _, m in cmds]


def read_truth(out: Path):
    """(ticks, events) from truth.jsonl."""
    ticks, events = [], []
    p = Path(out) / "truth.jsonl"
    if not p.is_file():
        return ticks, events
    for line in p.read_text().splitlines():
        if not line.strip():
            continue
        try:
            d = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut by a kill
        (events if "event" in d else ticks).append(d)
    return ticks, events


def read_json(p: Path):
    try:
        return json.loads(Path(p).read_text())
    except (OSError, json.JSONDecodeError):
        return None


def read_jsonl(p: Path) -> list[dict]:
    """The records of a JSON-lines file ([] when it is missing); a line that does not parse
    (a flight cut short mid-line) is skipped."""
    p = Path(p)
    if not p.is_file():
        return []
    out = []
    for line in p.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            pass
    return out
