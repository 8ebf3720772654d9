"""Campaigns through ArduCopter or PX4 SITL side by side (e.g. mppid and ArduCopter's own GUIDED
position controller over the same missions and seeds): one markdown row per mission and
controller. Errors are the simulated truth's (ap_score.py), means over the successful
flights (max: the largest of any); `estimate` is the same against the autopilot's own
position estimate (what either controller saw). Folders given one label are one campaign
(flown in batches: seeds 51-58, 59-66, ...)."""
from __future__ import annotations

from pathlib import Path
from statistics import mean

from . import survey
from .results import load_campaign


def _m(vals, fmt="{:.3f}", agg=mean):
    vals = [v for v in vals if isinstance(v, (int, float))]
    return fmt.format(agg(vals)) if vals else "-"


def _leg_key(r):
    return "tracking_rmse" if r.get("tracking_rmse") is not None else "hover_rmse"


def _load(rs) -> str:
    """The 1-minute load average over the flights (start and end of each; PX4 flights record
    it: the machine is shared and SIH lags under load), or '-'."""
    vals = [v[0] for r in rs for v in ((r.get("load_avg") or {}).get("start"), (r.get("load_avg") or {}).get("end"))
            if v]
    return f"{min(vals):.1f}-{max(vals):.1f}" if vals else "-"


def table(folders: list[Path], labels: list[str]) -> str:
    camps: dict[str, list] = {}   # folders under one label: one campaign flown in batches
    for f, label in zip(folders, labels):
        camps.setdefault(label, []).extend(load_campaign(f).runs)
    camps = list(camps.items())
    missions = list(dict.fromkeys(r["scenario"] for _, runs in camps for r in runs))  # first-seen order, once each
    surveys = [m for m in missions if any("waypoints_reached" in r for _, runs in camps for r in runs
                                          if r["scenario"] == m)]
    missions = [m for m in missions if m not in surveys]
    survey_lines = survey.TABLE_HEAD + [row for m in surveys for row in survey.table_rows(m, camps)] if surveys else []
    if not missions:
        return "\n".join(survey_lines) + "\n"
    with_load = any(r.get("load_avg") for _, runs in camps for r in runs)
    lines = ["| mission | controller | flights | success | RMS error [m] | largest error [m] | RMS, estimate [m] "
             "| largest tilt [deg] | failures |" + (" load |" if with_load else ""),
             "|---|---|---:|---:|---:|---:|---:|---:|---|" + ("---|" if with_load else "")]
    for m in missions:
        for label, runs in camps:
            rs = [r for r in runs if r["scenario"] == m]
            if not rs:
                continue
            ok = [r for r in rs if r.get("success")]
            legs = [leg for r in ok for k, leg in (r.get("legs") or {}).items() if not k.endswith("_hold")
                    or r.get("tracking_rmse") is None]
            fails = "; ".join(sorted({str(r.get("reason")) for r in rs if not r.get("success")})) or "-"
            lines.append(f"| {m} | {label} | {len(rs)} | {len(ok)}/{len(rs)} | "
                         f"{_m([r.get(_leg_key(r)) for r in ok])} | {_m([leg['max'] for leg in legs], agg=max)} | "
                         f"{_m([leg['rmse_estimate'] for leg in legs])} | "
                         f"{_m([r.get('max_tilt_deg') for r in rs], '{:.0f}', max)} | {fails} |"
                         + (f" {_load(rs)} |" if with_load else ""))
    return "\n".join(lines + ([""] + survey_lines if survey_lines else [])) + "\n"
