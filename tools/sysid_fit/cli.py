"""tools/sysid: the rate model's parameters from a flight log (docs/sysid.md).

    tools/sysid fit LOG [--vehicle IN.yaml] [--out OUT.yaml] [--report FIT.json]
                        [--holdout 0.3] [--lockstep-latency S] [--truth SCENARIO.yaml]
    tools/sysid fit FLIGHT.BIN --dataflash --vehicle IN.yaml ...      (ArduPilot dataflash)
    tools/sysid fit FLIGHT.ulg --vehicle IN.yaml ...                  (PX4 ULog: by its suffix, or --ulog)

Fits per body axis gain, time constant and delay, the one delay the daemon's latency
compensation takes (daemon.latency.actuation_delay_ms), the mass a newton of command flies
(or, through the bridge, the hover throttle) and the drag, on the first (1 - holdout) of the
log; predicts the held-out rest 0.5 s ahead from each state with the prior model (the input
vehicle file) and the fitted one, and writes the fitted vehicle file. Exit 0, or 1 with a
message naming what was missing.
"""
from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

import numpy as np
import yaml

from . import lag as lag_fit
from . import logs
from .evaluate import prediction_errors
from .fit import MIN_EXCITATION, Grid, excited_axes, fit_common_delay, fit_rate_axis, fit_thrust, fixed_axis
from .model import RateModel

DEFAULT_VEHICLE = logs.ROOT / "config" / "vehicles" / "sim_rate_1kg.yaml"
AXES = ("x", "y", "z")


def truth_of(scenario: Path) -> dict:
    """The plant's own values in a mppid-sim scenario (what a fit on its flight should find)."""
    sc = yaml.safe_load(scenario.read_text())
    p = (sc.get("plant") or {}).get("params") or {}
    out = {"mass": p.get("mass", 1.0), "drag": p.get("drag", 0.0),
           "delay": float((sc.get("timing") or {}).get("actuation_delay", 0.0))}
    for a in AXES:
        out[f"tau_{a}"] = p.get(f"rate_tau_{a}", 0.05)
        out[f"gain_{a}"] = p.get(f"rate_gain_{a}", 1.0)
    return out


def fitted_vehicle(prior: dict, data: logs.FlightData, thrust, delay: float, axes, transport_s: float, name: str,
                   source: str) -> tuple[dict, RateModel]:
    """The fitted vehicle file, and the model it makes mppid fly. Through the bridge (the log
    holds its hover throttle h0) the mass stays the airframe's and the hover throttle moves:
    a newton of command then buys 1/thrust.mass, as measured; without one (mppid-sim), the
    mass is what a newton buys."""
    v = dict(prior)
    v["name"] = name
    if data.hover_thrust is not None:
        v["hover_thrust"] = round(data.hover_thrust * thrust.mass / prior["mass"], 4)
    else:
        v["mass"] = round(thrust.mass, 4)
    v["drag"] = round(max(0.0, thrust.drag * v["mass"] / thrust.mass), 4)
    v["rate_response"] = {"tau": [round(f.tau, 4) for f in axes], "gain": [round(f.gain, 4) for f in axes],
                          "delay": round(max(0.0, delay - transport_s), 4)}
    prior_path = Path(prior.get("path", prior["name"])).resolve()
    if prior_path.is_relative_to(logs.ROOT):
        prior_path = prior_path.relative_to(logs.ROOT)
    v["description"] = f"Fitted by tools/sysid from {source} on {datetime.date.today().isoformat()} (prior: {prior_path})."
    model = RateModel(thrust.mass, v["gravity"], thrust.drag, [f.tau for f in axes], [f.gain for f in axes], delay)
    return v, model


def prior_axis(prior: dict, data: logs.FlightData, axis: int, delay: float, grid: Grid):
    """An axis the flight did not excite keeps the prior's gain and time constant."""
    rr = prior["rate_response"]
    return fixed_axis(data, axis, float(rr["gain"][axis]), float(rr["tau"][axis]), delay, grid)


def read_flight(a, prior: dict) -> logs.FlightData:
    """The log: ArduPilot dataflash (--dataflash), PX4 ULog (--ulog or .ulg), else mppid's LCM log."""
    if a.dataflash:
        return logs.read_dataflash(a.log, prior["mass"], prior["gravity"], prior["hover_thrust"])
    if a.ulog or Path(a.log).suffix == ".ulg":
        return logs.read_ulog(a.log, prior["mass"], prior["gravity"], prior["hover_thrust"])
    return logs.read_lcm(a.log, a.lockstep_latency)


def fit_figures(delay, thrust, thrust_own, axes, own, excited) -> dict:
    """The report's "fit": the common delay, the thrust fit, each axis's fit beside its own-delay fit."""
    return {
        "delay_s": delay, "mass_kg": thrust.mass, "drag_n_s_m": thrust.drag, "accel_m_s2": thrust.accel,
        "thrust_delay_s": thrust_own.delay, "thrust_rmse_m_s2": thrust.rmse,
        "axes": {AXES[i]: {"gain": axes[i].gain, "tau_s": axes[i].tau, "rmse_rad_s": axes[i].rmse,
                           "own_delay_s": own[i].delay, "own_gain": own[i].gain, "own_tau_s": own[i].tau}
                 for i in range(3)},
        "kept_prior": [AXES[i] for i in range(3) if i not in excited],
    }


def fit_command(a) -> int:
    from mppi_mavlink import vehicle as vehicle_file

    prior = vehicle_file.load(a.vehicle)
    if prior["model"] != "quadrotor_rate":
        print(f"sysid: {a.vehicle} describes a {prior['model']}; tools/sysid fits the rate model", file=sys.stderr)
        return 1
    data = read_flight(a, prior)
    split = data.split_time(1.0 - a.holdout)
    counted = sum(t1 - t0 for t0, t1 in data.spans())
    train, held = data.between(data.t[0], split), data.between(split, data.t[-1] + 1.0)
    grid = Grid(train)
    excited = [i for i in excited_axes(train, a.min_excitation) if AXES[i] not in a.keep_prior]
    delay, axes = fit_common_delay(train, grid, excited)
    axes = [f if i in excited else prior_axis(prior, train, i, delay, grid) for i, f in enumerate(axes)]
    own = [fit_rate_axis(train, i, grid) for i in range(3)]
    thrust = fit_thrust(train, grid, delay, prior["gravity"])
    thrust_own = fit_thrust(train, grid, gravity=prior["gravity"])
    name = a.name or f"{prior['name']}_sysid"
    fitted, model = fitted_vehicle(prior, data, thrust, delay, axes, a.transport_ms * 1e-3, name, Path(a.log).name)
    prior_model = RateModel.from_vehicle(prior)
    report = {
        "log": str(a.log), "clock": data.clock, "notes": data.notes, "states": int(len(data.t)),
        "commands": int(len(data.u)), "fit_s": (1.0 - a.holdout) * counted, "held_out_s": a.holdout * counted,
        "engaged_s": None if data.engaged is None else counted,
        "hover_thrust_logged": data.hover_thrust,
        "fit": fit_figures(delay, thrust, thrust_own, axes, own, excited),
        "vehicle": {k: v for k, v in fitted.items() if k != "path"},
        "held_out": {"prior": prediction_errors(prior_model, held), "fitted": prediction_errors(model, held)},
    }
    if a.structure:
        report["structure"] = structure_report(train, grid, axes)
    if a.truth:
        report["truth"] = truth_report(Path(a.truth), thrust, delay, axes)
    print_report(report)
    if a.out:
        vehicle_file.dump(fitted, a.out, header=f"tools/sysid fit {a.log}\nheld-out 0.5 s prediction: "
                          + json.dumps(report["held_out"]["fitted"]))
        print(f"vehicle file: {a.out}")
    if a.report:
        Path(a.report).write_text(json.dumps(report, indent=2) + "\n")
    return 0


def structure_report(train, grid, axes) -> dict:
    """Each axis's first-order fit beside a second-order one (--structure)."""
    from .structure import fit_second_order
    second = [fit_second_order(train, i, grid) for i in range(3)]
    return {AXES[i]: {"first_order_rmse_rad_s": axes[i].rmse, "second_order_rmse_rad_s": second[i].rmse,
                      "gain": second[i].gain, "wn_rad_s": second[i].wn, "zeta": second[i].zeta,
                      "delay_s": second[i].delay} for i in range(3)}


def truth_report(path: Path, thrust, delay: float, axes) -> dict:
    """The fit against the simulator's truth (--truth): each parameter's error in percent."""
    truth = truth_of(path)
    got = {"mass": thrust.mass, "drag": thrust.drag, "delay": delay}
    for i, ax in enumerate(AXES):
        got[f"tau_{ax}"], got[f"gain_{ax}"] = axes[i].tau, axes[i].gain
    return {k: {"truth": truth[k], "fitted": got[k],
                "error_pct": (100.0 * (got[k] - truth[k]) / truth[k]) if truth[k] else None}
            for k in truth}


def print_report(r: dict):
    f = r["fit"]
    print(f"{r['log']}: {r['states']} states, {r['commands']} commands ({r['clock']}); "
          f"fitted on {r['fit_s']:.1f} s, held out {r['held_out_s']:.1f} s")
    if r["engaged_s"] is not None:
        print(f"  bridge engaged {r['engaged_s']:.1f} s: only that flight fitted and held out")
    for ax, v in f["axes"].items():
        kept = " (kept at the prior: not excited, or --keep-prior)" if ax in f["kept_prior"] else ""
        print(f"  rate {ax}: gain {v['gain']:.3f}  tau {1e3 * v['tau_s']:.1f} ms  (own delay {1e3 * v['own_delay_s']:.1f} ms)"
              f"  rmse {v['rmse_rad_s']:.3f} rad/s{kept}")
    print(f"  delay {1e3 * f['delay_s']:.1f} ms (thrust alone {1e3 * f['thrust_delay_s']:.1f} ms); mass {f['mass_kg']:.4f} kg; "
          f"drag {f['drag_n_s_m']:.4f} N s/m; external accel {np.round(f['accel_m_s2'], 3).tolist()} m/s^2")
    for k in ("prior", "fitted"):
        e = r["held_out"][k]
        print(f"  held-out {e['horizon_s']} s prediction, {k:6s}: position {e['position_m']:.3f} m, velocity "
              f"{e['velocity_m_s']:.3f} m/s, attitude {e['attitude_deg']:.2f} deg, rates {e['rate_rad_s']:.3f} rad/s "
              f"({e['starts']} starts)")
    for ax, v in (r.get("structure") or {}).items():
        print(f"  rate {ax} as a second-order response: rmse {v['second_order_rmse_rad_s']:.3f} rad/s (first-order "
              f"{v['first_order_rmse_rad_s']:.3f}): wn {v['wn_rad_s']:.1f} rad/s, zeta {v['zeta']:.2f}, gain "
              f"{v['gain']:.3f}, delay {1e3 * v['delay_s']:.0f} ms")
    for k, v in (r.get("truth") or {}).items():
        err = "" if v["error_pct"] is None else f"  {v['error_pct']:+.1f} %"
        print(f"  truth {k}: {v['truth']:.4f}  fitted {v['fitted']:.4f}{err}")


def lag_command(a) -> int:
    """`tools/sysid estimate-lag FLIGHT`: the estimate's lag against the truth; with --out, the
    vehicle file (--vehicle) with that estimate_lag written."""
    r = lag_fit.estimate_lag(a.flight, a.min_speed)
    for key, what in (("mppid_state", "the states mppid flew on (bridge)"), ("estimator", "the estimator alone")):
        v = r.get(key)
        if v is None:
            continue
        bound = "  (at the search's bound: check the clocks)" if v["at_bound"] else ""
        print(f"{what}: lag {1e3 * v['lag_s']:.1f} ms over {v['samples']} samples at {v['speed_m_s']:.1f} m/s; "
              f"along-track {v['along_at_0_m']:+.3f} m -> {v['along_at_lag_m']:+.3f} m, RMS {v['rms_at_0_m']:.3f} -> "
              f"{v['rms_at_lag_m']:.3f} m{bound}")
    if a.report:
        a.report.write_text(json.dumps(r, indent=2) + "\n")
    if a.out:
        from mppi_mavlink import vehicle as vehicle_file
        best = r.get("mppid_state") or r["estimator"]
        v = vehicle_file.load(a.vehicle)
        v["estimate_lag"] = round(max(0.0, best["lag_s"]), 4)
        note = (f"estimate_lag {1e3 * v['estimate_lag']:.1f} ms: tools/sysid estimate-lag {a.flight} "
                f"({datetime.date.today().isoformat()})")
        vehicle_file.dump(v, a.out, header=note)
        print(f"wrote {a.out} (estimate_lag {v['estimate_lag']} s)")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/sysid", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit", help="fit the rate model to a flight log and write the vehicle file")
    f.add_argument("log", type=Path)
    f.add_argument("--vehicle", type=Path, default=DEFAULT_VEHICLE, help="the vehicle file the log was flown with (prior)")
    f.add_argument("--out", type=Path, help="write the fitted vehicle file here")
    f.add_argument("--report", type=Path, help="write the fit and the held-out errors as JSON")
    f.add_argument("--name", help="the fitted vehicle's name (default: the prior's + _sysid)")
    f.add_argument("--holdout", type=float, default=0.3, help="the last fraction of the log kept for evaluation")
    f.add_argument("--lockstep-latency", type=float, default=None, metavar="S",
                   help="lock-step log flown with a fixed latency (tools/sitl --latency S)")
    f.add_argument("--transport-ms", type=float, default=0.2,
                   help="the daemon's daemon.latency.transport_ms (subtracted from the delay written)")
    f.add_argument("--min-excitation", type=float, default=MIN_EXCITATION, metavar="RAD_S",
                   help="an axis whose commanded rate varies less (standard deviation) keeps the prior's gain and tau")
    f.add_argument("--keep-prior", type=lambda s: s.split(","), default=[], metavar="AXES",
                   help="body axes (x,y,z) that keep the prior's gain and tau whatever the flight shows")
    f.add_argument("--dataflash", action="store_true", help="LOG is an ArduPilot dataflash log (.BIN)")
    f.add_argument("--ulog", action="store_true", help="LOG is a PX4 ULog (the default for *.ulg; needs pyulog)")
    f.add_argument("--truth", type=Path, help="a mppid-sim scenario: compare the fit with its plant")
    f.add_argument("--structure", action="store_true",
                   help="also fit a second-order rate response per axis: does the first-order model express it?")
    g = sub.add_parser("estimate-lag", help="how far the autopilot's position estimate trails the truth "
                                            "(the vehicle file's estimate_lag)")
    g.add_argument("flight", type=Path, help="a flight folder (truth.jsonl, flight.lcmlog) or a truth log")
    g.add_argument("--vehicle", type=Path, default=DEFAULT_VEHICLE, help="the vehicle file to write it into (--out)")
    g.add_argument("--out", type=Path, help="write the vehicle file with estimate_lag here")
    g.add_argument("--report", type=Path, help="write the result as JSON")
    g.add_argument("--min-speed", type=float, default=1.0, help="only samples moving faster (m/s)")
    a = ap.parse_args(argv)
    if a.cmd == "estimate-lag":
        try:
            return lag_command(a)
        except (lag_fit.LagError, logs.LogError, OSError) as e:
            print(f"sysid: {e}", file=sys.stderr)
            return 1
    if not 0.05 <= a.holdout <= 0.8:
        ap.error("--holdout must be in [0.05, 0.8]")
    if not set(a.keep_prior) <= set(AXES):
        ap.error("--keep-prior takes body axes x, y, z (comma-separated)")
    try:
        return fit_command(a)
    except (logs.LogError, ValueError, OSError) as e:
        print(f"sysid: {e}", file=sys.stderr)
        return 1
