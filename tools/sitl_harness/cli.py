"""tools/sitl: list scenarios, run one, run a campaign, re-plot a result folder. One parser
and one function per subcommand (cmd_*); a UsageError is `sitl: <message>`, exit 2."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from . import paths

# --controller: mppid, its DDP baseline, the hover stand-in, and the autopilots' own (guided:
# ArduCopter's GUIDED; px4: PX4's offboard position control; auto: an uploaded mission in the
# autopilot's own mission mode, ArduCopter's AUTO with BendyRuler or PX4's AUTO.MISSION; loiter:
# ArduCopter's Loiter, pushed towards a trunk; position: PX4's Position mode, pushed likewise).
CONTROLLERS = ["mppid", "ddp", "standin", "guided", "px4", "auto", "loiter", "position"]


class UsageError(Exception):
    """Arguments that cannot be flown: printed as `sitl: <message>`, exit 2."""


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    try:
        return a.func(a)
    except UsageError as e:
        print(f"sitl: {e}", file=sys.stderr)
        return 2


def build_parser() -> argparse.ArgumentParser:
    from .tune import add_tune_parser

    ap = argparse.ArgumentParser(prog="sitl", description="mppid software-in-the-loop flights")
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="scenario names, then mission names (config/missions), one a line"
                   ).set_defaults(func=cmd_list)
    _add_run_parser(sub)
    _add_campaign_parser(sub)
    _add_report_parsers(sub)
    _add_robustness_parser(sub)
    o = sub.add_parser("overlay", help="print a settings overlay's --set pairs (for mppid)")
    o.add_argument("file", type=Path)
    o.set_defaults(func=cmd_overlay)
    add_tune_parser(sub).set_defaults(func=cmd_tune)
    p = sub.add_parser("plot", help="re-make the plots of a result folder")
    p.add_argument("folder", type=Path)
    p.set_defaults(func=cmd_plot)
    _add_refusals_parser(sub)
    return ap


# ---- parsers -------------------------------------------------------------------------------
def _add_run_parser(sub):
    r = sub.add_parser("run", help="fly one scenario; writes a result folder; exit 0 on success, 1 on failure")
    r.set_defaults(func=cmd_run)
    r.add_argument("--scenario", required=True, help="a name from `sitl list` or a YAML file")
    r.add_argument("--seed", type=int, default=1)
    r.add_argument("--backend", choices=["cpu", "cuda", "auto"], default="cpu")
    r.add_argument("--out", type=Path, default=None, help="result folder (default results/<scenario>-s<seed>-<time>)")
    r.add_argument("--realtime", action="store_true", help="real-time clock instead of lock-step")
    lat = r.add_mutually_exclusive_group()
    lat.add_argument("--ideal", action="store_true",
                     help="lock-step without charging the controller's latency (algorithm studies only)")
    lat.add_argument("--latency", type=float, default=None, metavar="SECONDS",
                     help="lock-step: charge this fixed latency instead of the measured one (repeatable runs)")
    r.add_argument("--controller", choices=CONTROLLERS, default="mppid",
                   help="ddp: mppid --controller ddp, the MPC-DDP baseline; standin: a hover stand-in (tests the "
                        "simulator without the daemon); guided: ArduCopter's own position controller (--autopilot "
                        "ardupilot); px4: PX4's own offboard position control (--autopilot px4); auto: a mission "
                        "uploaded to the autopilot flown in its own mission mode (ArduCopter's AUTO with BendyRuler, "
                        "PX4's AUTO.MISSION; config/missions/survey_*.yaml); loiter: "
                        "ArduCopter's Loiter pushed towards a sensed trunk, mppid not flying (loiter_toward_trunk); "
                        "position: PX4's Position mode pushed likewise, its collision prevention fed by the map "
                        "(position_toward_trunk)")
    _autopilot_args(r)
    r.add_argument("--overlay", action="append", default=[], type=Path, metavar="FILE.yaml",
                   help="settings overlay (e.g. from `sitl tune`): its keys become --set pairs, before --set")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="passed to mppid --set")
    r.add_argument("--param", action="append", default=[], metavar="T:KEY=VALUE",
                   help="a parameter update sent in flight, T seconds (state time) after the first state, e.g. "
                        "2:mppi.rollouts=512; the answers go to score.json (param_results)")
    r.add_argument("--timeout", type=float, default=0.0, help="wall-clock limit [s] (default from the scenario)")
    r.add_argument("--fault", action="append", default=[], metavar="ACTION@T",
                   help="--autopilot px4: a failsafe flight; ACTION (kill_mppid, stop_bridge, gcs_hold, gcs_position, "
                        "link_cut:SECONDS) T seconds after the first path leg starts (docs/px4.md)")
    r.add_argument("--autopilot-param", action="append", default=[], metavar="NAME=VALUE",
                   help="--autopilot px4: a PX4 parameter over config/px4's files (e.g. COM_OBL_RC_ACT=0)")
    r.add_argument("--kill-controller-after", type=float, default=0.0, help=argparse.SUPPRESS)
    r.add_argument("--lcm-port", type=int, default=0, help=argparse.SUPPRESS)   # campaigns: one bus per flight
    r.add_argument("--parent-pid", type=int, default=0, help=argparse.SUPPRESS)  # stop when this process dies
    r.add_argument("--niceness", type=int, default=None, help=argparse.SUPPRESS)  # Ray: the driver's niceness
    r.add_argument("--no-plots", action="store_true", help="skip path/traces/timing.png")
    r.add_argument("--view", action="store_true",
                   help="the live 3D view in the browser (tools/view; rollouts on at 5 Hz); prints its URL; "
                        "flight.rrd after the flight")
    r.add_argument("--view-hold", type=float, default=0.0, metavar="SECONDS",
                   help="with --view: keep the view serving this long after the flight")
    r.add_argument("--view-wait", type=float, default=0.0, metavar="SECONDS",
                   help="with --view: serve this long before the flight starts (time to open the page)")
    r.add_argument("--view-port", type=int, default=9090, help="with --view: the web viewer's port (gRPC: +786)")
    r.add_argument("--rrd", action="store_true", help="also write flight.rrd (the log in rerun's format, tools/view)")
    r.add_argument("--quiet", action="store_true")


def _add_campaign_parser(sub):
    c = sub.add_parser("campaign", help="seeds x scenarios, summary table with Wilson intervals")
    c.set_defaults(func=cmd_campaign)
    c.add_argument("--scenarios", required=True, help="comma-separated scenario names and/or YAML files")
    c.add_argument("--seeds", default="10", help="a count (from --first-seed) or seeds: 51-70, 1,4,9-12")
    c.add_argument("--first-seed", type=int, default=1)
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--engine", choices=["local", "ray"], default="local",
                   help="local: processes on this machine; ray: one Ray task per flight")
    c.add_argument("--address", default=None,
                   help="ray: an existing cluster (auto, HOST:PORT, ray://HOST:PORT); default: start a local one")
    c.add_argument("--jobs", type=int, default=None,
                   help="flights at a time (default 2; ray on a cluster: its CPUs / --cpus-per-flight; real time: 1)")
    c.add_argument("--realtime-jobs", type=int, default=1, metavar="N",
                   help="with --realtime: N flights at once, each pinned (taskset) to its own 1/N of the CPUs "
                        "(default 1: one at a time)")
    c.add_argument("--cpus-per-flight", type=float, default=1.0, help="ray: CPUs a flight task asks for")
    c.add_argument("--backend", choices=["cpu", "cuda", "auto"], default="cpu")
    c.add_argument("--controller", choices=CONTROLLERS, default="mppid",
                   help="mppid (MPPI), ddp (mppid --controller ddp: the MPC-DDP baseline), the stand-in, guided "
                        "(ArduCopter's position controller, --autopilot ardupilot), auto (an uploaded survey in the "
                        "autopilot's mission mode: ArduCopter's AUTO with BendyRuler, PX4's AUTO.MISSION), loiter "
                        "(ArduCopter's Loiter pushed at a trunk), position (PX4's Position mode pushed at a trunk) "
                        "or px4 "
                        "(PX4's offboard position control, --autopilot px4)")
    _autopilot_args(c)
    c.add_argument("--realtime", action="store_true")
    clat = c.add_mutually_exclusive_group()
    clat.add_argument("--ideal", action="store_true", help="lock-step without charging the controller's latency")
    clat.add_argument("--latency", type=float, default=None, metavar="SECONDS",
                      help="lock-step: charge this fixed latency instead of the measured one")
    c.add_argument("--overlay", action="append", default=[], type=Path, metavar="FILE.yaml",
                   help="settings overlay: its keys become --set pairs, before --set")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="passed to mppid --set")
    c.add_argument("--no-plots", action="store_true",
                   help="no per-flight plots (faster; `tools/sitl plot FOLDER` makes them later)")


def _add_report_parsers(sub):
    cmp_ = sub.add_parser("compare", help="two campaign folders: same outcomes? (lock-step: engine-independent)")
    cmp_.set_defaults(func=cmd_compare)
    cmp_.add_argument("a", type=Path)
    cmp_.add_argument("b", type=Path)
    cmp_.add_argument("--no-truth", action="store_true", help="skip comparing each flight's truth.jsonl path")

    t = sub.add_parser("table", help="campaigns side by side (e.g. real time and lock-step): one row per scenario")
    t.set_defaults(func=cmd_table)
    t.add_argument("folders", type=Path, nargs="+")
    t.add_argument("--names", default=None, help="comma-separated column names, one per folder")

    vs = sub.add_parser("versus", help="campaigns of different controllers side by side (markdown table)")
    vs.set_defaults(func=cmd_versus)
    vs.add_argument("folders", type=Path, nargs="+", help="campaign folders (summary.json), same scenarios and seeds")
    vs.add_argument("--labels", default=None, help="comma-separated, one per folder (default: the folder names)")
    vs.add_argument("--json", type=Path, default=None, help="also write the rows here")

    sc = sub.add_parser("speed-curve", help="success against a setting: campaigns flown at --set KEY=V, KEY "
                        "cost.max_speed unless --key says another (markdown)")
    sc.set_defaults(func=cmd_speed_curve)
    sc.add_argument("folders", type=Path, nargs="+")
    sc.add_argument("--key", default="cost.max_speed", help="the setting the campaigns differ in (e.g. mppi.rollouts)")
    sc.add_argument("--png", type=Path, default=None, help="also draw success against the limit here")
    sc.add_argument("--json", type=Path, default=None, help="also write the rows here")

    apt = sub.add_parser("autopilot-table", help="campaigns through ArduCopter or PX4 SITL side by side (markdown)")
    apt.set_defaults(func=cmd_autopilot_table)
    apt.add_argument("folders", type=Path, nargs="+")
    apt.add_argument("--labels", default=None, help="comma-separated, one per folder (default: the folder names)")


def _add_robustness_parser(sub):
    rb = sub.add_parser("robustness", help="the robustness map: mass, motor constant, wind, delay, noise "
                                           "(docs/robustness.md)")
    rb.set_defaults(func=cmd_robustness)
    rb.add_argument("--scenarios", default="forest_4m,rate_track_circle_fast",
                    help="comma-separated base scenarios (quadrotor plants)")
    rb.add_argument("--seeds", default="51-55", help="seeds per cell: 51-55, 1,4,9-12, or a count from 1")
    rb.add_argument("--out", type=Path, required=True)
    rb.add_argument("--realtime", action="store_true", help="real time (the map's figures); default lock-step")
    rb.add_argument("--latency", type=float, default=None, metavar="SECONDS", help="lock-step: a fixed latency")
    rb.add_argument("--realtime-jobs", type=int, default=1, metavar="N",
                    help="real-time flights at once, each pinned to its own 1/N of the cores (as campaign's)")
    rb.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="passed to mppid --set")


def _autopilot_args(p):
    from .flights import PLANTS

    p.add_argument("--autopilot", choices=list(PLANTS), default="sim",
                   help="sim: mppid-sim (scenarios); ardupilot: ArduCopter SITL, px4: PX4 SITL with SIH, through "
                        "the MAVLink bridge, flying missions (config/missions) in real time")
    p.add_argument("--ardupilot-bin", default=None, metavar="PATH",
                   help="the ArduCopter SITL binary (<ardupilot>/build/sitl/bin/arducopter; default "
                        "$MPPID_ARDUPILOT_BIN)")
    p.add_argument("--px4-bin", default=None, metavar="PATH",
                   help="PX4 SITL with SIH (<PX4>/build/px4_sitl_sih/bin/px4; default $MPPID_PX4_BIN)")


def _add_refusals_parser(sub):
    rf = sub.add_parser("refusals", help="the missions mppid must refuse, uploaded to a real autopilot's SITL: "
                                         "each refused before anything flies? (markdown table, refusals.json)")
    rf.set_defaults(func=cmd_refusals)
    rf.add_argument("--autopilot", choices=["ardupilot", "px4"], required=True)
    rf.add_argument("--out", type=Path, default=None,
                    help="result folder (default results/refusals-<autopilot>-<time>)")
    rf.add_argument("--ardupilot-bin", default=None, metavar="PATH", help="default $MPPID_ARDUPILOT_BIN")
    rf.add_argument("--px4-bin", default=None, metavar="PATH", help="default $MPPID_PX4_BIN")


# ---- checks shared by run and campaign -----------------------------------------------------
def _autopilot_check(a) -> str:
    """Why the autopilot options do not fit the others ('' when they do)."""
    own = {"ardupilot": ("guided", "auto", "loiter"), "px4": ("px4", "auto", "position")}  # each autopilot's own
    owners = [autopilot for autopilot, ctrls in own.items() if a.controller in ctrls]
    if owners and a.autopilot not in owners:
        return (f"--controller {a.controller} is {' or '.join(owners)}'s own controller: it needs --autopilot "
                f"{' or '.join(owners)}")
    if a.autopilot in own:
        if a.controller not in ("mppid",) + own[a.autopilot]:
            return f"--autopilot {a.autopilot} flies --controller {' or '.join(('mppid',) + own[a.autopilot])}"
        if not a.realtime:
            return f"--autopilot {a.autopilot} flies in real time (its SITL runs on the wall clock): add --realtime"
    return ""


def _overlay_sets(files) -> list[str]:
    """The --set pairs of settings overlay files, in order."""
    from .overlay import OverlayError, load_sets

    try:
        return [kv for f in files for kv in load_sets(f)]
    except OverlayError as e:
        raise UsageError(str(e)) from None


def _flight_args(a) -> None:
    """run and campaign: the autopilot options, the overlays before --set, the clock options."""
    why = _autopilot_check(a)
    if why:
        raise UsageError(why)
    a.set = _overlay_sets(a.overlay) + a.set


def _lockstep_options_check(a) -> None:
    if (a.ideal or a.latency is not None) and a.realtime:
        raise UsageError("--ideal and --latency are lock-step options")


# ---- the subcommands -----------------------------------------------------------------------
def cmd_list(a) -> int:
    print("\n".join(paths.scenario_names() + paths.mission_names()))
    return 0


def cmd_overlay(a) -> int:
    print(" ".join(f"--set {kv}" for kv in _overlay_sets([a.file])))
    return 0


def _run_spec(a):
    """The FlightSpec of `sitl run`'s arguments; UsageError when they cannot be flown."""
    from .flights.base import LCM_URL, FlightSpec, lcm_url_for_port
    from .inject import parse_update

    out = a.out or paths.ROOT / "results" / f"{Path(a.scenario).stem}-s{a.seed}-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        url = lcm_url_for_port(a.lcm_port) if a.lcm_port else LCM_URL
    except ValueError as e:
        raise UsageError(f"--lcm-port: {e}") from None
    _lockstep_options_check(a)
    spec = FlightSpec(scenario=a.scenario, seed=a.seed, out=out, backend=a.backend, realtime=a.realtime,
                      ideal=a.ideal, latency=a.latency, controller=a.controller, wall_timeout=a.timeout, sets=a.set,
                      kill_controller_after=a.kill_controller_after, lcm_url=url, plots=not a.no_plots,
                      params=a.param, autopilot=a.autopilot, ardupilot_bin=a.ardupilot_bin, px4_bin=a.px4_bin, view=a.view,
                      view_hold=a.view_hold, view_wait=a.view_wait, view_port=a.view_port, rrd=a.rrd,
                      faults=a.fault, autopilot_params=a.autopilot_param)
    try:
        _fault_check(a)
        for u in a.param:
            parse_update(u)
        paths.scenario_label(a.scenario)
    except (ValueError, FileNotFoundError) as e:
        raise UsageError(str(e)) from None
    return spec


def _fault_check(a) -> None:
    """--fault and --autopilot-param: PX4 flights only, well-formed (ValueError otherwise)."""
    from .px4_faults import parse_fault

    if (a.fault or a.autopilot_param) and a.autopilot != "px4":
        raise ValueError("--fault and --autopilot-param are for --autopilot px4")
    if a.fault and a.controller != "mppid":
        raise ValueError("--fault: failsafe flights fly mppid")
    for f in a.fault:
        parse_fault(f)
    for kv in a.autopilot_param:
        if "=" not in kv:
            raise ValueError(f"--autopilot-param {kv!r}: expected NAME=VALUE")


def _set_niceness(niceness: int) -> None:
    """A Ray worker runs at niceness 15; its flight runs at the campaign's, like a local one."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except OSError as e:
        print(f"sitl: cannot set niceness {niceness} (kept {os.getpriority(os.PRIO_PROCESS, 0)}): {e}",
              file=sys.stderr)


def cmd_run(a) -> int:
    from .fly import fly, watch_parent

    _flight_args(a)
    spec = _run_spec(a)
    if a.parent_pid:
        watch_parent(a.parent_pid)
    if a.niceness is not None:
        _set_niceness(a.niceness)
    try:
        score = fly(spec)
    except KeyboardInterrupt:
        print("sitl: interrupted; flight stopped and cleaned up", file=sys.stderr)
        return 130
    if not a.quiet:
        keys = ["success", "reason", "time_to_goal", "min_clearance", "tracking_rmse", "mean_speed",
                "deadline_misses", "compute_ms_p99", "wall_s"]
        print(json.dumps({k: score.get(k) for k in keys}))
        print(f"results: {spec.out}")
    return 0 if score.get("success") else 1


def _scenario_list(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


def cmd_campaign(a) -> int:
    from .campaign import parse_seeds, resolve_scenarios, run_campaign
    from .fly import interrupt_on_stop_signals

    _flight_args(a)
    interrupt_on_stop_signals()
    names = _scenario_list(a.scenarios)
    try:
        resolve_scenarios(names)
        seeds = parse_seeds(a.seeds, a.first_seed)
        if a.address and a.engine != "ray":
            raise ValueError("--address needs --engine ray")
    except (FileNotFoundError, ValueError) as e:
        raise UsageError(str(e)) from None
    _lockstep_options_check(a)
    try:
        run_campaign(names, seeds, a.out, jobs=a.jobs, backend=a.backend, controller=a.controller,
                     realtime=a.realtime, sets=a.set, engine=a.engine, address=a.address,
                     cpus_per_flight=a.cpus_per_flight, ideal=a.ideal, latency=a.latency,
                     realtime_jobs=a.realtime_jobs, plots=not a.no_plots, autopilot=a.autopilot,
                     ardupilot_bin=a.ardupilot_bin, px4_bin=a.px4_bin)
    except KeyboardInterrupt:
        print("\nsitl: campaign interrupted", file=sys.stderr)
        return 130
    except RuntimeError as e:
        raise UsageError(str(e)) from None
    print((Path(a.out) / "summary.md").read_text())
    return 0


def cmd_robustness(a) -> int:
    from .campaign import parse_seeds
    from .robustness import run_map

    if a.realtime and a.latency is not None:
        raise UsageError("--latency is a lock-step option")
    try:
        md = run_map(_scenario_list(a.scenarios), parse_seeds(a.seeds), a.out, a.realtime, sets=a.set,
                     latency=a.latency, realtime_jobs=a.realtime_jobs)
    except (FileNotFoundError, ValueError) as e:
        raise UsageError(str(e)) from None
    except KeyboardInterrupt:
        print("\nsitl: robustness map interrupted", file=sys.stderr)
        return 130
    print(md.read_text())
    return 0


def cmd_compare(a) -> int:
    from .campaign import compare_campaigns
    from .results import load_campaign

    diffs = compare_campaigns(a.a, a.b, truth=not a.no_truth)
    runs = len(load_campaign(a.a).runs)
    for d in diffs:
        print(d)
    print(f"{runs} runs: " + ("identical outcomes" + ("" if a.no_truth else " and truth paths") if not diffs
                              else f"{len(diffs)} differences"))
    return 0 if not diffs else 1


def cmd_table(a) -> int:
    from .sidebyside import table

    names = [n.strip() for n in a.names.split(",")] if a.names else None
    if names and len(names) != len(a.folders):
        raise UsageError("--names needs one name per folder")
    try:
        print(table(a.folders, names))
    except FileNotFoundError as e:
        raise UsageError(str(e)) from None
    return 0


def _labels(a) -> list[str]:
    return a.labels.split(",") if a.labels else [f.name for f in a.folders]


def cmd_versus(a) -> int:
    from .versus import versus

    try:
        table, rows = versus(a.folders, _labels(a))
    except (ValueError, FileNotFoundError, KeyError) as e:
        raise UsageError(f"versus: {e}") from None
    print(table, end="")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=2))
    return 0


def cmd_speed_curve(a) -> int:
    from .speed_curve import main

    try:
        print(main(a.folders, a.png, a.json, a.key), end="")
    except FileNotFoundError as e:
        raise UsageError(str(e)) from None
    return 0


def cmd_autopilot_table(a) -> int:
    from .ap_table import table

    print(table(a.folders, _labels(a)), end="")
    return 0


def cmd_tune(a) -> int:
    from .fly import interrupt_on_stop_signals
    from .tune import main_tune

    interrupt_on_stop_signals()
    return main_tune(a)


def cmd_refusals(a) -> int:
    from .flights.base import FlightError
    from .refusals import run

    out = a.out or paths.ROOT / "results" / f"refusals-{a.autopilot}-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        return run(a.autopilot, out, a.ardupilot_bin if a.autopilot == "ardupilot" else a.px4_bin)
    except FlightError as e:
        raise UsageError(str(e)) from None


def cmd_plot(a) -> int:
    from .plots import plot_flight

    for f in plot_flight(a.folder):
        print(f)
    return 0
