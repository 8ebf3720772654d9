"""`mppid-mission check`: the propellers-off check before a first offboard flight
(docs/first-flight.md, section 5). mppid answers every state the bridge publishes, engaged or
not; this prints, twice a second, the attitude and body rates the autopilot reports beside the
thrust and body rates mppid would command (their mean over the half second: a sampling
controller's single command is noisy), and whether each rate command turns the vehicle back
towards level: tilt the vehicle by hand and the roll and pitch commands must oppose the tilt.
A sign the other way is a frame mix-up: do not fly. Read the first second after each tilt:
held still with its propellers off the vehicle does not answer, and mppid's disturbance and
delay estimates soon explain the tilt away (the commands shrink to noise, `small` below
0.3 rad/s); level it, tilt again.

Both in the body frame mppid uses (x forward, y left, z up; the bridge converts from the
autopilot's NED/FRD): right side down is roll > 0, nose down is pitch > 0.
"""
from __future__ import annotations

import math
import time

from mppi_mavlink.layout import QuadrotorRate as Q

TILT_DEG = 5.0          # below this the vehicle counts as level (no sign to check)
SMALL_RATE = 0.3        # rad/s: a mean rate command below this has no sign to check
MODES = {0: "normal", 1: "hold_plan", 2: "failsafe"}


def euler_deg(x) -> tuple[float, float, float]:
    """Roll, pitch, yaw [deg] of the state's attitude quaternion (w, x, y, z; body to world)."""
    w, qx, qy, qz = x[Q.QUAT]
    roll = math.atan2(2 * (w * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * qy - qz * qx))))
    yaw = math.atan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


def verdict(tilt_deg: float, rate_cmd: float) -> str:
    """'level', 'small', 'ok' (the command turns back towards level) or 'WRONG SIGN'."""
    if abs(tilt_deg) < TILT_DEG:
        return "level"
    if abs(rate_cmd) < SMALL_RATE:
        return "small"
    return "ok" if tilt_deg * rate_cmd < 0 else "WRONG SIGN"


def line(x, u, mode: int, hover_n: float | None) -> str:
    r, p, y = euler_deg(x)
    share = f" ({u[Q.THRUST] / hover_n:.2f} x hover)" if hover_n else ""
    return (f"autopilot: roll {r:+6.1f} pitch {p:+6.1f} yaw {y:+6.1f} deg, rates {x[Q.WX]:+.2f} {x[Q.WY]:+.2f} "
            f"{x[Q.WZ]:+.2f} rad/s | mppid ({MODES.get(mode, mode)}): thrust {u[Q.THRUST]:5.2f} N{share}, rates "
            f"{u[Q.RATE_X]:+.2f} {u[Q.RATE_Y]:+.2f} {u[Q.RATE_Z]:+.2f} rad/s | roll {verdict(r, u[Q.RATE_X])}, "
            f"pitch {verdict(p, u[Q.RATE_Y])}")


def run(lcm_url: str, seconds: float, hover_n: float | None, say=print) -> int:
    """Prints until `seconds` (0: Ctrl-C). 0 when states and mppid's answers came, 1 when not
    (mppid or the bridge not running: the message says which)."""
    import lcm
    from mppi_mavlink import lcm_types
    t = lcm_types.import_mppi_lcm()
    last = {"state": None, "command": None}
    commands: list = []  # since the last line
    lc = lcm.LCM(lcm_url)
    lc.subscribe("MPPI_STATE", lambda ch, d: last.__setitem__("state", t.vehicle_state_t.decode(d)))

    def on_command(ch, d):
        last["command"] = t.command_t.decode(d)
        commands.append(list(last["command"].u))
    lc.subscribe("MPPI_COMMAND", on_command)
    end = time.monotonic() + seconds if seconds > 0 else math.inf
    shown = 0
    next_line = time.monotonic() + 0.5
    try:
        while time.monotonic() < end:
            lc.handle_timeout(50)
            if time.monotonic() < next_line:
                continue
            next_line += 0.5
            s, c = last["state"], last["command"]
            if s is None or c is None:
                say("waiting: " + ("no state from the bridge" if s is None else "no command from mppid"))
                continue
            if s.nx != 13 or c.n < 4:
                say(f"not the rate task (state nx {s.nx}, command n {c.n}): the bridge flies quadrotor_rate_track")
                return 1
            mean = [sum(col) / len(commands) for col in zip(*commands)] if commands else list(c.u)
            commands.clear()
            text = line(s.x, mean, c.mode, hover_n)
            shown += 1
            say(text)
    except KeyboardInterrupt:
        pass
    return 0 if shown else 1
