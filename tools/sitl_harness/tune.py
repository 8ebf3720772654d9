"""`tools/sitl tune`: an Optuna study over controller settings, scored by SITL flights.

    tools/sitl tune --scenarios forest_4m --seeds 1-20 --params lambda,nu,sigma --trials 40 \\
        --out results/tune/forest4 [--range lambda=20:500] [--engine ray] [--jobs 2]

Objective (maximised): the success rate over scenarios x seeds, then a secondary figure
that only orders trials with the same number of successes:
    value = (successes + 0.99 * b) / flights,   b in [0, 1]
(a value lies in [k/n, (k+1)/n) for k successes of n, so one more success always wins;
study.md and each trial's user attributes give the success count itself). b, over the
successful flights, is 1 / (1 + mean/scale) for a figure to minimise (time to goal /
scenario duration, tracking RMSE / the scenario's max_rmse) or clearance / (1 + clearance)
for the mean minimum clearance [m] (--secondary; `auto`: time to goal for goal scenarios,
RMSE otherwise).

Pruning (--prune, default bound,median): after each flight the trial reports its success
rate so far; `bound` stops a trial once its successes so far plus its remaining flights
cannot reach the best complete trial's successes (it could no longer win: exact);
`median` is Optuna's MedianPruner (5 trials first, then after half the flights).

Storage: SQLite (OUT/study.db), so a study killed at any point resumes by running the
same command again: complete and pruned trials are kept, a trial that was running (or
failed) is marked failed and its parameters are flown again first, and the study runs
until it holds --trials complete or pruned trials. One tune process per study (a lock).

Parameters (--params; a search range is [lo, hi] and may be given with --range NAME=LO:HI,
:log or :linear after it to choose the scale). "x" is the value in the task's settings
file (after --set/--overlay):

| name                | settings key              | default range             | scale  |
|---------------------|---------------------------|---------------------------|--------|
| lambda              | mppi.lambda               | [x/10, 10x]               | log    |
| nu                  | mppi.nu                   | [max(1, x/4), 4x]         | log    |
| sigma               | mppi.sigma (every channel | factor [0.5, 2] on x      | log    |
|                     | scaled by one factor)     |                           |        |
| rollouts            | mppi.rollouts (integer)   | [x/2, 2x]                 | log    |
| horizon             | mppi.horizon (integer)    | [x/2, 3x/2]               | linear |
| control_cost_scale  | mppi.control_cost_scale   | [x/10, 10x]               | log    |
| smoothing_window    | mppi.smoothing_window     | odd integers in [1, 9]    | linear |
| SECTION.FIELD       | that key (model.*, cost.*,| [x/10, 10x] (a list: one  | log    |
|                     | mppi.*, daemon.*)         | factor [0.5, 2] on x)     |        |

A name that is not in the table and not a settings key, a range the settings validation
rejects (the study asks the daemon itself: `mppid --config ... --set KEY=LO`, then HI,
over memq://) or a key without a value in the settings file and no --range stops the
study before its first flight, naming the field.

Seeds: tuning uses seeds 1-50 only (the project reports on 51-70); larger seeds are
refused unless --allow-test-seeds.

Output: OUT/study.db, OUT/best.yaml (the best trial's settings as an overlay, rewritten
after every trial: `tools/sitl run|campaign --overlay OUT/best.yaml`,
`mppid --config TASK.yaml $(tools/sitl overlay OUT/best.yaml)`), OUT/best_config.yaml
(the whole settings file with the overlay applied: `mppid --config OUT/best_config.yaml`),
OUT/study.md (every trial), OUT/trials/NNNN/<scenario>/seed_NNNN (each flight's score).
"""
from __future__ import annotations

import argparse
import fcntl
import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import yaml

from . import overlay as ovl
from . import paths

MAX_TUNING_SEED = 50


class TuneError(ValueError):
    pass


@dataclass
class ParamDef:
    key: str
    kind: str          # float | int | odd | factor (a list scaled by one factor)
    lo: float          # default range: relative to x (rel) or absolute
    hi: float
    log: bool
    rel: bool = True
    floor: float | None = None


TABLE = {
    "lambda": ParamDef("mppi.lambda", "float", 0.1, 10.0, True),
    "nu": ParamDef("mppi.nu", "float", 0.25, 4.0, True, floor=1.0),
    "sigma": ParamDef("mppi.sigma", "factor", 0.5, 2.0, True),
    "rollouts": ParamDef("mppi.rollouts", "int", 0.5, 2.0, True),
    "horizon": ParamDef("mppi.horizon", "int", 0.5, 1.5, False),
    "control_cost_scale": ParamDef("mppi.control_cost_scale", "float", 0.1, 10.0, True),
    "smoothing_window": ParamDef("mppi.smoothing_window", "odd", 1, 9, False, rel=False),
}
SECTIONS = ("mppi", "model", "cost", "daemon")


@dataclass
class Param:
    name: str
    key: str
    kind: str
    lo: float
    hi: float
    log: bool
    base: object = None  # the value in the settings (a list for kind factor)

    def suggest(self, trial):
        if self.kind == "int":
            return trial.suggest_int(self.name, int(self.lo), int(self.hi), log=self.log)
        if self.kind == "odd":
            return trial.suggest_int(self.name, int(self.lo), int(self.hi), step=2)
        return trial.suggest_float(self.name, self.lo, self.hi, log=self.log)

    def setting(self, v):
        """--set text of the sampled value v."""
        if self.kind == "factor":
            vec = [float(f"{float(b) * v:.6g}") for b in self.base]
            return f"{self.key}={ovl._value_text(vec, self.key)}"
        if self.kind in ("int", "odd"):
            return f"{self.key}={int(v)}"
        return f"{self.key}={ovl._value_text(float(f'{v:.6g}'), self.key)}"

    def describe(self):
        return {"key": self.key, "kind": self.kind, "lo": self.lo, "hi": self.hi, "log": self.log}


def _lookup(doc, key):
    node = doc
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def parse_ranges(items) -> dict:
    out = {}
    for it in items:
        name, eq, rng = it.partition("=")
        parts = rng.split(":")
        if not eq or len(parts) not in (2, 3):
            raise TuneError(f"--range {it}: expected NAME=LO:HI[:log|:linear]")
        try:
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise TuneError(f"--range {it}: LO and HI must be numbers") from None
        scale = parts[2] if len(parts) == 3 else None
        if scale not in (None, "log", "linear"):
            raise TuneError(f"--range {it}: scale must be log or linear")
        if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
            raise TuneError(f"--range {name.strip()}: need finite LO < HI, got {lo:g}:{hi:g}")
        out[name.strip()] = (lo, hi, scale)
    return out


def resolve_params(names, ranges: dict, settings: dict, config_name: str) -> list[Param]:
    """Params from names, the table, the ranges, and the settings (the task's file with the
    user's --set applied). TuneError naming the field on anything unknown or unusable."""
    out = []
    for name in names:
        d = _param_def(name)
        base = _lookup(settings, d.key)
        kind = d.kind
        if kind == "float" and isinstance(base, list):
            kind = "factor"
            d = ParamDef(d.key, "factor", 0.5, 2.0, True)
        if kind == "factor" and not (isinstance(base, list) and base and
                                     all(isinstance(x, (int, float)) for x in base)):
            raise TuneError(f"{d.key}: expected a list of numbers in {config_name} to scale, found {base!r}")
        lo, hi, log = _range(name, d, kind, base, ranges, config_name)
        if kind in ("int", "odd"):
            lo, hi = _integer_range(d, kind, lo, hi)
        if log and lo <= 0:
            raise TuneError(f"{d.key}: a log-scale range must be > 0 (got {lo:g}:{hi:g}; add :linear)")
        if not lo < hi:
            raise TuneError(f"{d.key}: empty range {lo:g}:{hi:g}")
        out.append(Param(name, d.key, kind, float(lo), float(hi), log, base))
    keys = [p.key for p in out]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise TuneError(f"{', '.join(sorted(dup))}: named twice in --params")
    return out


def _param_def(name: str) -> ParamDef:
    """The table's entry, or a float scaled 0.1x..10x for any other settings key SECTION.FIELD."""
    d = TABLE.get(name)
    if d is None:
        sec = name.split(".", 1)[0]
        if "." not in name or sec not in SECTIONS or not name.split(".", 1)[1]:
            raise TuneError(f"{name}: unknown tuning parameter (known: {', '.join(TABLE)}, "
                            f"or a settings key {'|'.join(SECTIONS)}.FIELD)")
        d = ParamDef(name, "float", 0.1, 10.0, True)
    return d


def _range(name: str, d: ParamDef, kind: str, base, ranges: dict, config_name: str) -> tuple:
    """(lo, hi, log): the user's --range, the table's absolute one, or the table's relative one
    around the task's value (`base`; 1 for a factor)."""
    if name in ranges:
        lo, hi, scale = ranges[name]
        return lo, hi, d.log if scale is None else scale == "log"
    if not d.rel:
        return d.lo, d.hi, d.log
    x = 1.0 if kind == "factor" else base
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise TuneError(f"{d.key}: no number for it in {config_name} (found {base!r}): "
                        f"give its range with --range {name}=LO:HI")
    if x <= 0:
        raise TuneError(f"{d.key}: its value in {config_name} is {x}, no range relative to it: "
                        f"give one with --range {name}=LO:HI")
    lo, hi = x * d.lo, x * d.hi
    if d.floor is not None:
        lo = max(lo, d.floor)
    return lo, hi, d.log


def _integer_range(d: ParamDef, kind: str, lo, hi) -> tuple[int, int]:
    """The integers (odd ones for "odd") within [lo, hi]; TuneError when none fit."""
    lo, hi = math.ceil(lo), math.floor(hi)
    if kind == "odd":
        lo += 1 - lo % 2 if lo % 2 == 0 else 0
        hi -= 1 - hi % 2 if hi % 2 == 0 else 0
    if hi <= lo:
        raise TuneError(f"{d.key}: no integer range in [{lo}, {hi}]")
    return lo, hi


def validate_with_daemon(cfg: Path, base_sets, params: list[Param], backend: str) -> None:
    """The daemon's own settings validation, at both ends of every range (all parameters at
    their lower ends, then at their upper ends; a failure is narrowed to one parameter)."""
    mppid = paths.find_binary("mppid")
    if mppid is None:
        raise TuneError("mppid not built: the ranges are checked by the daemon's settings validation "
                        f"(searched {', '.join(map(str, paths.build_dirs()))})")

    def check(sets):
        cmd = [str(mppid), "--config", str(cfg), "--lcm-url", "memq://", "--duration", "0.05", "--backend", backend,
               "--log-level", "error"]
        for kv in sets:
            cmd += ["--set", kv]
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return "the daemon did not stop within 120 s"
        if p.returncode == 0:
            return None
        msg = (p.stderr + p.stdout).strip().splitlines()
        msg = [m.split("invalid settings: ", 1)[-1] for m in msg if "error" in m or "invalid" in m] or msg
        return (msg[-1] if msg else f"exit code {p.returncode}")

    err = check(base_sets)
    if err:
        raise TuneError(f"the settings before tuning are rejected: {err}")
    for end in ("lo", "hi"):
        val = lambda p: p.lo if end == "lo" else p.hi  # noqa: E731
        if check(list(base_sets) + [p.setting(val(p)) for p in params]) is None:
            continue
        for p in params:
            err = check(list(base_sets) + [p.setting(val(p))])
            if err:
                raise TuneError(f"{p.key}: the settings validation rejects the {'lower' if end == 'lo' else 'upper'} "
                                f"end of the range {p.lo:g}:{p.hi:g} ({p.setting(val(p))}): {err}")
        err = check(list(base_sets) + [p.setting(val(p)) for p in params])
        raise TuneError(f"the ranges' {'lower' if end == 'lo' else 'upper'} ends together are rejected: {err}")


# ---- the objective ---------------------------------------------------------------------
def secondary_kind(name: str, scen_docs) -> str:
    if name != "auto":
        return name
    types = {(d.get("success") or {}).get("type", "goal") for d in scen_docs}
    return "time_to_goal" if types == {"goal"} else "tracking_rmse"


def secondary_bonus(kind: str, scores, scen_docs_by_label) -> tuple[float | None, float]:
    """(the mean figure over the successful flights, b in [0, 1])."""
    ok = [s for s in scores if s.get("success")]
    vals, norm = [], []
    for s in ok:
        v = s.get(kind)
        if v is None or not isinstance(v, (int, float)) or not math.isfinite(v):
            continue
        doc = scen_docs_by_label.get(s.get("scenario"), {})
        if kind == "time_to_goal":
            scale = float((doc.get("timing") or {}).get("duration", 30.0))
        elif kind == "tracking_rmse":
            scale = float((doc.get("success") or {}).get("max_rmse", 0.5))
        else:
            scale = 1.0
        vals.append(v)
        norm.append(v / scale if scale > 0 else v)
    if not vals:
        return None, 0.0
    mean, mnorm = sum(vals) / len(vals), sum(norm) / len(norm)
    if kind == "min_clearance":
        return mean, max(0.0, mnorm) / (1.0 + max(0.0, mnorm))
    return mean, 1.0 / (1.0 + max(0.0, mnorm))


def add_tune_parser(sub):
    t = sub.add_parser("tune", help="Optuna study over settings (success rate over seeds 1-50)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    t.add_argument("--scenarios", required=True, help="comma-separated scenario names and/or YAML files (one task)")
    t.add_argument("--seeds", required=True, help="a count from 1, or seeds: 1-20, 1,4,9-12 (at most 50)")
    t.add_argument("--params", required=True, help="comma-separated: " + ", ".join(TABLE) + ", or SECTION.FIELD")
    t.add_argument("--range", action="append", default=[], metavar="NAME=LO:HI[:log|:linear]")
    t.add_argument("--trials", type=int, default=30, help="complete + pruned trials the study should hold")
    t.add_argument("--out", type=Path, default=None, help="study folder (default results/tune/<study>)")
    t.add_argument("--study", default="tune", help="study name in the storage")
    t.add_argument("--secondary", choices=["auto", "time_to_goal", "tracking_rmse", "min_clearance"], default="auto")
    t.add_argument("--prune", default="bound,median", help="bound, median, both (default) or none")
    t.add_argument("--sampler-seed", type=int, default=1)
    t.add_argument("--engine", choices=["local", "ray"], default="local")
    t.add_argument("--address", default=None, help="ray: an existing cluster")
    t.add_argument("--jobs", type=int, default=None, help="flights at a time")
    t.add_argument("--cpus-per-flight", type=float, default=1.0)
    t.add_argument("--backend", choices=["cpu", "cuda", "auto"], default="cpu")
    t.add_argument("--controller", choices=["mppid", "standin"], default="mppid", help=argparse.SUPPRESS)
    t.add_argument("--realtime", action="store_true")
    t.add_argument("--overlay", action="append", default=[], type=Path, metavar="FILE.yaml",
                   help="settings applied to every trial (before --set)")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="applied to every trial")
    t.add_argument("--keep-flights", action="store_true", help="keep each flight's log and plots (default: score only)")
    t.add_argument("--allow-test-seeds", action="store_true", help="allow seeds above 50 (the report seeds)")
    return t


def _tuning_seeds(a) -> list[int]:
    """--seeds: 1-MAX_TUNING_SEED only, unless --allow-test-seeds."""
    from .campaign import parse_seeds

    try:
        seeds = parse_seeds(a.seeds, 1)
    except ValueError as e:
        raise TuneError(str(e)) from None
    bad = [s for s in seeds if s > MAX_TUNING_SEED]
    if bad and not a.allow_test_seeds:
        raise TuneError(f"--seeds: tuning uses seeds 1-{MAX_TUNING_SEED} only (got {bad[0]}"
                        f"{' ...' if len(bad) > 1 else ''}); seeds above are for reporting "
                        "(--allow-test-seeds to override)")
    return seeds


def _settings_file(docs: dict) -> Path:
    """The one controller settings file the scenarios share (TuneError when they differ)."""
    cfgs = set()
    for label, doc in docs.items():
        mp = doc.get("mppid") or {}
        cfgs.add(paths.ROOT / mp["config"] if mp.get("config") else paths.TASKS / f"{doc['task']}.yaml")
    if len(cfgs) != 1:
        raise TuneError("the scenarios use different controller settings files "
                        f"({', '.join(sorted(str(c) for c in cfgs))}): tune one task at a time")
    return cfgs.pop()


def _base_sets(a) -> list:
    """--overlay files' settings, then --set: applied to every trial."""
    try:
        over = [kv for f in a.overlay for kv in ovl.load_sets(f)]
    except ovl.OverlayError as e:
        raise TuneError(str(e)) from None
    return over + list(a.set)


class Study:
    def __init__(self, a):
        from .campaign import resolve_scenarios

        self.a = a
        self.seeds = _tuning_seeds(a)
        names = [s.strip() for s in a.scenarios.split(",") if s.strip()]
        try:
            self.scenarios = resolve_scenarios(names)
        except (FileNotFoundError, ValueError) as e:
            raise TuneError(str(e)) from None
        self.docs = {label: yaml.safe_load(paths.scenario_path(spec).read_text()) for spec, label in self.scenarios}
        self.cfg = _settings_file(self.docs)
        self.base_sets = _base_sets(a)
        self.params = self._resolve_params()
        # The scenario's own mppid.set come first in a flight, like in `sitl run`.
        scen_sets = [str(kv) for d in self.docs.values() for kv in ((d.get("mppid") or {}).get("set") or [])]
        validate_with_daemon(self.cfg, scen_sets + self.base_sets, self.params, a.backend)
        self.secondary = secondary_kind(a.secondary, list(self.docs.values()))
        self.prune = {p.strip() for p in a.prune.replace("both", "bound,median").split(",") if p.strip()}
        if not self.prune <= {"bound", "median", "none"}:
            raise TuneError(f"--prune {a.prune}: use bound, median, both or none")
        self.out = Path(a.out or paths.ROOT / "results" / "tune" / a.study).resolve()
        if a.trials < 1:
            raise TuneError("--trials: at least 1")

    def _resolve_params(self) -> list[Param]:
        """--params and --range against the settings file with the base sets applied."""
        a = self.a
        settings = ovl.merge_config(self.cfg, self.base_sets)
        names = [p.strip() for p in a.params.split(",") if p.strip()]
        if not names:
            raise TuneError("--params: no parameter")
        rel = self.cfg.relative_to(paths.ROOT) if self.cfg.is_relative_to(paths.ROOT) else self.cfg
        params = resolve_params(names, parse_ranges(a.range), settings, str(rel))
        unknown_ranges = set(parse_ranges(a.range)) - set(names)
        if unknown_ranges:
            raise TuneError(f"--range {', '.join(sorted(unknown_ranges))}: not in --params")
        return params

    def definition(self) -> dict:
        """What the study is; a resumed study must be the same."""
        return {"scenarios": [label for _, label in self.scenarios], "seeds": self.seeds,
                "params": {p.name: p.describe() for p in self.params}, "config": str(self.cfg),
                "base_sets": self.base_sets, "secondary": self.secondary, "realtime": bool(self.a.realtime),
                "controller": self.a.controller, "backend": self.a.backend}


def main_tune(a) -> int:
    try:
        st = Study(a)
    except TuneError as e:
        print(f"sitl tune: {e}", file=sys.stderr)
        return 2
    try:
        import optuna
    except ImportError:
        print("sitl tune: needs the `optuna` package (requirements.txt; tools/setup.sh installs it)", file=sys.stderr)
        return 2
    st.out.mkdir(parents=True, exist_ok=True)
    lock = open(st.out / "study.lock", "w")
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        print(f"sitl tune: another tune process is running the study in {st.out}", file=sys.stderr)
        return 2
    try:
        return _run_study(st, optuna)
    except KeyboardInterrupt:
        print("\nsitl tune: interrupted; run the same command again to resume", file=sys.stderr)
        return 130
    except (TuneError, RuntimeError) as e:
        print(f"sitl tune: {e}", file=sys.stderr)
        return 2


def _open_study(st: Study, optuna):
    from optuna.trial import TrialState

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = optuna.storages.RDBStorage(f"sqlite:///{st.out / 'study.db'}")
    sampler = optuna.samplers.TPESampler(seed=st.a.sampler_seed)
    pruner = (optuna.pruners.MedianPruner(n_startup_trials=5, n_warmup_steps=max(1, len(st.seeds) * len(st.scenarios) // 2))
              if "median" in st.prune else optuna.pruners.NopPruner())
    study = optuna.create_study(study_name=st.a.study, storage=storage, direction="maximize", sampler=sampler,
                                pruner=pruner, load_if_exists=True)
    want = json.loads(json.dumps(st.definition()))
    have = study.user_attrs.get("definition")
    if have is None:
        study.set_user_attr("definition", want)
    elif have != want:
        diff = sorted(k for k in set(have) | set(want) if have.get(k) != want.get(k))
        raise TuneError(f"study '{st.a.study}' in {st.out} was made with other {', '.join(diff)}: "
                        "use the same arguments to resume it, or another --study/--out")
    # Resume: a trial left running by a killed process (or failed) is closed as failed and
    # its parameters are flown again first.
    requeued = set(study.user_attrs.get("requeued", []))
    for t in study.get_trials(deepcopy=False):
        if t.state == TrialState.RUNNING:
            storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
            print(f"sitl tune: trial {t.number} was left running (killed?): marked failed, flown again",
                  file=sys.stderr)
        if t.state in (TrialState.RUNNING, TrialState.FAIL) and t.number not in requeued and t.params:
            study.enqueue_trial(t.params, user_attrs={"rerun_of": t.number}, skip_if_exists=False)
            requeued.add(t.number)
    study.set_user_attr("requeued", sorted(requeued))
    return study


def _counted(study):
    from optuna.trial import TrialState

    return [t for t in study.get_trials(deepcopy=False) if t.state in (TrialState.COMPLETE, TrialState.PRUNED)]


def _run_study(st: Study, optuna) -> int:
    from .engine import make_engine

    study = _open_study(st, optuna)
    left = st.a.trials - len(_counted(study))
    n_flights = len(st.seeds) * len(st.scenarios)
    print(f"sitl tune: study '{st.a.study}' in {st.out}: {len(_counted(study))} trials stored, {max(0, left)} to go; "
          f"{n_flights} flights a trial; params " +
          ", ".join(f"{p.key} [{p.lo:g}, {p.hi:g}]{' log' if p.log else ''}" for p in st.params), file=sys.stderr)
    if left > 0:
        eng = make_engine(st.a.engine, jobs=1 if st.a.realtime else st.a.jobs, address=st.a.address,
                          cpus_per_flight=st.a.cpus_per_flight)
        try:
            def objective(trial):
                return _objective(st, study, trial, eng, optuna)
            while len(_counted(study)) < st.a.trials:
                study.optimize(objective, n_trials=1, catch=())
                _write_outputs(st, study)
        finally:
            eng.close()
    _write_outputs(st, study)
    best = _best(study)
    if best is None:
        print("sitl tune: no complete trial", file=sys.stderr)
        return 1
    print(f"sitl tune: best trial {best.number}: {best.user_attrs.get('successes')}/{best.user_attrs.get('flights')} "
          f"successes, {st.secondary} {best.user_attrs.get('secondary')}; overlay {st.out / 'best.yaml'}")
    return 0


def _best(study):
    from optuna.trial import TrialState

    done = [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]
    return max(done, key=lambda t: (t.value, -t.number)) if done else None


def _objective(st: Study, study, trial, eng, optuna):
    """One trial: its settings flown over scenarios x seeds on `eng`; prunes as --prune says."""
    from .campaign import make_jobs
    from .engine import Progress, run_flights

    values = {p.name: p.suggest(trial) for p in st.params}
    trial_sets = [p.setting(values[p.name]) for p in st.params]
    folder = st.out / "trials" / f"{trial.number:04d}"
    # Seed-major, so a pruning decision has seen every scenario.
    jobs = make_jobs(st.scenarios, st.seeds, folder, backend=st.a.backend, controller=st.a.controller,
                     realtime=st.a.realtime, sets=st.base_sets + trial_sets, plots=st.a.keep_flights)
    jobs.sort(key=lambda j: (st.seeds.index(j.seed), j.label))
    for k, j in enumerate(jobs):
        j.index = k
    best = _best(study)
    best_successes = int(best.user_attrs.get("successes", 0)) if best is not None else None
    state = {"done": 0, "ok": 0, "pruned": None}

    def on_result(job, score):
        state["done"] += 1
        state["ok"] += int(bool(score.get("success")))
        if not st.a.keep_flights:
            for f in ("flight.lcmlog", "truth.jsonl"):
                (Path(job.out) / f).unlink(missing_ok=True)
        left = len(jobs) - state["done"]
        trial.report(state["ok"] / state["done"], step=state["done"])
        if "bound" in st.prune and best_successes is not None and state["ok"] + left < best_successes:
            state["pruned"] = (f"bound: {state['ok']} successes after {state['done']} flights, "
                               f"at most {state['ok'] + left} < best {best_successes}")
            return True
        if "median" in st.prune and left > 0 and trial.should_prune():
            state["pruned"] = f"median: success rate {state['ok'] / state['done']:.2f} after {state['done']} flights"
            return True
        return False

    print(f"sitl tune: trial {trial.number}: " + " ".join(trial_sets), file=sys.stderr)
    scores = run_flights(eng, jobs, Progress(len(jobs)), on_result=on_result)
    trial.set_user_attr("sets", trial_sets)
    trial.set_user_attr("successes", state["ok"])
    trial.set_user_attr("flights", len(jobs))
    trial.set_user_attr("flown", len(scores))
    trial.set_user_attr("failures", sorted({(s.get("reason") or "?").split(" at t=")[0]
                                            for s in scores if not s.get("success")}))
    if state["pruned"]:
        trial.set_user_attr("pruned", state["pruned"])
        print(f"sitl tune: trial {trial.number} pruned ({state['pruned']})", file=sys.stderr)
        raise optuna.TrialPruned(state["pruned"])
    fig, b = secondary_bonus(st.secondary, scores, st.docs)
    trial.set_user_attr("secondary", fig)
    value = (state["ok"] + 0.99 * b) / len(jobs)
    print(f"sitl tune: trial {trial.number}: {state['ok']}/{len(jobs)} successes, {st.secondary} {fig}, "
          f"value {value:.4f}", file=sys.stderr)
    return value


def _write_outputs(st: Study, study):
    best = _best(study)
    trials = study.get_trials(deepcopy=False)
    lines = [f"# study {st.a.study}", "",
             f"scenarios {', '.join(label for _, label in st.scenarios)}; seeds {st.seeds[0]}-{st.seeds[-1]} "
             f"({len(st.seeds)}); objective: success rate, then {st.secondary}", "",
             "| trial | state | successes | " + st.secondary + " | value | settings | note |",
             "|---:|---|---:|---:|---:|---|---|"]
    for t in trials:
        ua = t.user_attrs
        sec = ua.get("secondary")
        lines.append(f"| {t.number} | {t.state.name.lower()} | {ua.get('successes', '-')}/{ua.get('flights', '-')} | "
                     f"{'-' if sec is None else f'{sec:.3f}'} | {'-' if t.value is None else f'{t.value:.4f}'} | "
                     f"{' '.join(ua.get('sets', []))} | {ua.get('pruned') or ('rerun of %s' % ua['rerun_of'] if 'rerun_of' in ua else '')} |")
    (st.out / "study.md").write_text("\n".join(lines) + "\n")
    if best is None:
        return
    sets = best.user_attrs.get("sets", [])
    head = (f"# tools/sitl tune: study '{st.a.study}', trial {best.number} of {len(trials)}: "
            f"{best.user_attrs.get('successes')}/{best.user_attrs.get('flights')} successes on "
            f"{', '.join(label for _, label in st.scenarios)}, seeds {st.seeds[0]}-{st.seeds[-1]}; "
            f"{st.secondary} {best.user_attrs.get('secondary')}\n"
            f"# Applies on top of {st.cfg.name}"
            + (f" with {' '.join(st.base_sets)}" if st.base_sets else "") +
            ": tools/sitl run --overlay best.yaml; mppid --config ... $(tools/sitl overlay best.yaml)\n")
    (st.out / "best.yaml").write_text(head + yaml.safe_dump(ovl.from_sets(sets), sort_keys=False,
                                                            default_flow_style=None))
    merged = ovl.merge_config(st.cfg, st.base_sets + sets)
    (st.out / "best_config.yaml").write_text(
        f"# {st.cfg.name} with the best trial's settings (study '{st.a.study}', trial {best.number})\n"
        + yaml.safe_dump(merged, sort_keys=False, default_flow_style=None))
