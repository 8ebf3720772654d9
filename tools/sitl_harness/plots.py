"""PNG plots of a flight's result folder (matplotlib, Agg): the path over the obstacle map
(top view and altitude), command and state traces, and the controller's timing."""
from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mppi_mavlink.layout import Cartpole, Racecar  # noqa: E402

from . import logs, timing  # noqa: E402

STATE_NAMES = {
    "quadrotor": ["x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r", "w1", "w2", "w3", "w4"],
    "quadrotor_rate": ["x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "p", "q", "r"],
    "quadrotor_rate_body": ["x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "p", "q", "r"],
    "cartpole": ["x", "x_dot", "theta", "theta_dot", "force"],
    "racecar": ["x", "y", "psi", "beta", "vx", "vy", "r", "delta", "Fx"],
}
CONTROL_NAMES = {
    "quadrotor": ["w1_des [rpm]", "w2_des", "w3_des", "w4_des"],
    "quadrotor_rate": ["thrust [N]", "p_des [rad/s]", "q_des", "r_des"],
    "quadrotor_rate_body": ["thrust [N]", "p_des [rad/s]", "q_des", "r_des"],
    "cartpole": ["f_des [N]"],
    "racecar": ["delta_des [rad]", "Fx_des [N]"],
}


def plot_flight(out: Path) -> list[Path]:
    out = Path(out)
    world = logs.read_json(out / "world.json")
    ticks, events = logs.read_truth(out)
    if world is None or not ticks:
        return []
    model, nx, nu, m = world["model"], world["nx"], world["nu"], world["vehicles"]
    t = np.array([tk["t"] for tk in ticks])
    X = np.array([[np.nan if v is None else v for v in tk["x"]] for tk in ticks], float)
    U = np.array([[np.nan if v is None else v for v in tk["u"]] for tk in ticks], float)
    made = [_path(out, world, t, X, ticks, events, model, nx, m), _traces(out, t, X, U, model, nx, nu, m)]
    made.append(_timing(out, ticks))
    return [p for p in made if p]


def _cartpole_path(out, world, t, X):
    fig = plt.figure(figsize=(11, 7.5))
    ax1, ax2 = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    ax1.plot(t, X[:, Cartpole.THETA], label="theta (0 = down)")
    ax1.axhline(np.pi, ls="--", c="k", lw=0.8, label="upright")
    ax1.axhline(-np.pi, ls="--", c="k", lw=0.8)
    ax1.set_ylabel("pole angle [rad]")
    ax1.legend()
    ax2.plot(t, X[:, Cartpole.X], label="cart x")
    ax2.set_ylabel("cart position [m]")
    ax2.set_xlabel("t [s]")
    fig.suptitle(f"{world['scenario']} seed {world['seed']}")
    p = out / "path.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return p


def _obstacles(ax1, world, ticks):
    """The obstacles (moving ones orange, with their velocity) and the moving ones' tracks."""
    for ob in world.get("obstacles", []):
        moving = ob[3] != 0 or ob[4] != 0
        ax1.add_patch(plt.Circle((ob[0], ob[1]), ob[2], color="tab:orange" if moving else "tab:green", alpha=0.35 if moving else 0.7))
        if moving:
            ax1.arrow(ob[0], ob[1], ob[3] * 0.5, ob[4] * 0.5, width=0.05, color="tab:orange")
    if any("obs" in tk for tk in ticks):
        tr = [tk["obs"] for tk in ticks if "obs" in tk]
        arr = np.array(tr, float)
        for k in range(arr.shape[1]):
            ax1.plot(arr[:, k, 0], arr[:, k, 1], c="tab:orange", lw=0.3, alpha=0.35)


def _path(out, world, t, X, ticks, events, model, nx, m):
    if model == "cartpole":
        return _cartpole_path(out, world, t, X)
    fig = plt.figure(figsize=(11, 7.5))
    ax1 = fig.add_subplot(3, 1, (1, 2))
    ax2 = fig.add_subplot(3, 1, 3)
    _obstacles(ax1, world, ticks)
    if model == "racecar":
        a = np.linspace(0, 2 * np.pi, 400)
        ax1.plot(13 * np.cos(a), 6 * np.sin(a), "k--", lw=0.8, label="track centre")
        ax1.plot(X[:, Racecar.X], X[:, Racecar.Y], lw=1.2, label="car")
        sp = np.hypot(X[:, Racecar.VX], X[:, Racecar.VY])
        ax2.plot(t, sp, label="speed")
        ax2.axhline(7.0, c="k", ls="--", lw=0.8)
        ax2.set_ylabel("speed [m/s]")
    else:
        ref = world.get("reference", {})
        if ref.get("kind") in ("circle", "figure_eight"):
            from .score import reference_eval
            rp = reference_eval(ref, np.linspace(0, t[-1], 1000))
            ax1.plot(rp[:, 0], rp[:, 1], "k--", lw=0.8, label="reference")
        for v in range(m):
            ax1.plot(X[:, v * nx], X[:, v * nx + 1], lw=1.2, label=f"vehicle {v}" if m > 1 else "path")
            ax2.plot(t, X[:, v * nx + 2], lw=1.0)
        for s in world.get("starts", []):
            ax1.plot(s[0], s[1], "bs", ms=5)
        for g in world.get("goals", []):
            if ref.get("kind") in ("waypoint", "hold"):
                ax1.add_patch(plt.Circle((g[0], g[1]), world.get("goal_radius", 1), fill=False, color="b"))
        ax2.axhline(world.get("ground_z", 0), c="brown", lw=1)
        ax2.set_ylabel("altitude [m]")
    for e in events:
        if e.get("event") == "collision":
            k = min(np.searchsorted(t, e["t"]), len(t) - 1)
            v = e.get("vehicle", 0)
            ax1.plot(X[k, v * nx], X[k, v * nx + 1], "rx", ms=12, mew=3)
    ax1.set_aspect("equal")
    ax1.set_xlabel("x [m]")
    ax1.set_ylabel("y [m]")
    if m <= 9:
        ax1.legend(loc="upper right", fontsize=7)
    ax2.set_xlabel("t [s]")
    fig.suptitle(f"{world['scenario']} seed {world['seed']} ({'lock-step' if world.get('lockstep') else 'real time'})")
    fig.tight_layout()
    p = out / "path.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return p


def _traces(out, t, X, U, model, nx, nu, m):
    names = STATE_NAMES.get(model, [f"x{i}" for i in range(nx)])
    cnames = CONTROL_NAMES.get(model, [f"u{i}" for i in range(nu)])
    groups = {"quadrotor": [(0, 3), (3, 6), (6, 9), (9, 12), (12, 16)],
              "quadrotor_rate": [(0, 3), (3, 6), (6, 10), (10, 13)],
              "quadrotor_rate_body": [(0, 3), (3, 6), (6, 10), (10, 13)],
              "cartpole": [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)],
              "racecar": [(0, 2), (2, 4), (4, 6), (6, 7), (7, 8), (8, 9)]}.get(model, [(0, nx)])
    rows = len(groups) + nu
    fig, axes = plt.subplots(rows, 1, figsize=(10, 1.6 * rows), sharex=True)
    v = 0  # the first vehicle of a team
    for ax, (a, b) in zip(axes, groups):
        for i in range(a, b):
            ax.plot(t, X[:, v * nx + i], lw=0.9, label=names[i])
        ax.legend(loc="upper right", fontsize=7, ncol=4)
    for j in range(nu):
        ax = axes[len(groups) + j]
        ax.step(t, U[:, v * nu + j], where="post", lw=0.9, c="tab:red")
        ax.set_ylabel(cnames[j], fontsize=7)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("state and applied command" + (" (vehicle 0)" if m > 1 else ""))
    fig.tight_layout()
    p = out / "traces.png"
    fig.savefig(p, dpi=80)
    plt.close(fig)
    return p


def _state_to_command(ax, ticks, tm):
    """The first panel: a state's sample time -> the command answering it leaving. In
    lock-step the simulator measures it per tick (it charges it); in real time the daemon
    does, per fresh cycle (command_t age_us + compute_us). Returns what it shows."""
    lat = [tk["lat_ms"] for tk in ticks if tk.get("lat_ms") is not None]
    if lat:
        ax.hist(lat, bins=50, color="tab:blue")
        ax.set_title("state -> command [ms] (sim, per cycle)", fontsize=9)
        return "simulator, per tick"
    samples = tm.get("state_to_command_samples_ms")
    if samples:
        p99 = tm["state_to_command_ms_p99"]
        ax.hist(samples, bins=50, color="tab:blue")
        ax.axvline(p99, c="k", ls="--", lw=0.8)
        ax.set_title(f"state sample -> command out [ms], daemon, real time\np99 {p99:.2f} over {len(samples)} "
                     f"cycles (of it state age: p99 {tm['state_age_ms_p99']:.2f})", fontsize=9)
        return "daemon, per fresh cycle (command_t age_us + compute_us)"
    ax.set_title("state -> command: no per-cycle times in the log", fontsize=9)
    return None


def _timing(out, ticks):
    """timing.png: the state-to-command time the simulator saw, the controller's compute time
    per cycle and the command period; the figures in the titles (timing.py's definitions,
    the same numbers as score.json) are also written to timing.json."""
    data = logs.read_lcm_log(out / "flight.lcmlog", {"MPPI_COMMAND", "MPPI_STATUS"})
    cmd_t = np.array([t for t, _ in data.get("MPPI_COMMAND", [])], float) / 1e3
    status = [m for _, m in data.get("MPPI_STATUS", [])]
    tm = timing.flight_timing(status, [m for _, m in data.get("MPPI_COMMAND", [])])
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    shown_state_to_command = _state_to_command(axes[0], ticks, tm)
    misses = int(max(m.misses for m in status)) if status else 0
    if tm["compute_samples_ms"]:
        axes[1].hist(tm["compute_samples_ms"], bins=50, color="tab:green")
        axes[1].axvline(tm["compute_ms_p99"], c="k", ls="--", lw=0.8)
        axes[1].set_title(f"compute per cycle [ms]: p99 {tm['compute_ms_p99']:.2f} over "
                          f"{len(tm['compute_samples_ms'])} cycles, max {tm['compute_ms_max']:.2f}, misses {misses}",
                          fontsize=9)
    elif status and tm["compute_ms_p99_worst_window"] is not None:
        # No per-cycle times: the per-window p99s, named as such.
        axes[1].hist([m.compute_ms_p99 for m in status], bins=30, color="tab:green")
        axes[1].set_title(f"compute p99 per status window [ms]: worst window {tm['compute_ms_p99_worst_window']:.2f}, "
                          f"misses {misses}", fontsize=9)
    else:
        axes[1].set_title("no controller_status_t", fontsize=9)
    if len(cmd_t) > 2:
        axes[2].hist(np.diff(cmd_t), bins=50, color="tab:purple")
        axes[2].set_title("command period [ms] (log receive times)", fontsize=9)
    for ax in axes:
        ax.set_ylabel("count")
    fig.tight_layout()
    p = out / "timing.png"
    fig.savefig(p, dpi=80)
    plt.close(fig)
    shown = {k: v for k, v in tm.items() if k not in ("compute_samples_ms", "state_to_command_samples_ms")}
    shown["compute_samples"] = len(tm["compute_samples_ms"] or [])
    shown["state_to_command_shown"] = shown_state_to_command
    (out / "timing.json").write_text(json.dumps(shown, indent=2))
    return p
