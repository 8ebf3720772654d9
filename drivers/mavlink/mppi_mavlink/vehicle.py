"""A vehicle file (config/vehicles/*.yaml, docs/vehicle.md): one airframe's mass, hover
thrust, limits and the response of its autopilot's rate loop.

mppid reads it in C++ (drivers/controller/src/vehicle.cpp: into the task's model and the
daemon's actuation delay); the bridge reads it here (its thrust map: mass, gravity, hover
thrust), and tools/sysid writes it. The schema is the same; test/mavlink/test_vehicle.py
checks that this reader and mppid accept and refuse the same files.
"""
from __future__ import annotations

import math
from pathlib import Path

import yaml

TOP = {"description", "name", "model", "mass", "gravity", "hover_thrust", "drag", "limits", "rate_response",
       "estimate_lag", "params"}
OWN_FIELDS = {"mass", "gravity", "drag"}


class VehicleError(ValueError):
    pass


def _num(where: str, field: str, v, lo: float, hi: float) -> float:
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or not lo <= v <= hi:
        raise VehicleError(f"{where}: {field}: must be in [{lo:g}, {hi:g}], got {v!r}")
    return float(v)


def _axes(where: str, field: str, v, lo: float, hi: float) -> list[float]:
    if isinstance(v, list):
        if len(v) != 3:
            raise VehicleError(f"{where}: {field}: expected 3 numbers (x, y, z) or one")
        return [_num(where, f"{field}[{i}]", x, lo, hi) for i, x in enumerate(v)]
    x = _num(where, field, v, lo, hi)
    return [x, x, x]


def _known(where: str, section: str, d, names: set[str]):
    if not isinstance(d, dict):
        raise VehicleError(f"{where}: {section or '(file)'}: expected a map")
    for k in d:
        if k not in names:
            raise VehicleError(f"{where}: {section + '.' if section else ''}{k}: unknown field")


def parse(doc, where: str = "vehicle file") -> dict:
    """A validated vehicle: the document with defaults filled in (gravity 9.81, drag 0,
    hover_thrust None, rate_response for quadrotor_rate)."""
    _known(where, "", doc, TOP)
    v = {"description": doc.get("description", "")}
    for key in ("name", "model"):
        if not isinstance(doc.get(key), str) or not doc[key]:
            raise VehicleError(f"{where}: {key}: expected a name")
        v[key] = doc[key]
    v["mass"] = _num(where, "mass", doc.get("mass"), 1e-3, 100.0)
    v["gravity"] = _num(where, "gravity", doc.get("gravity", 9.81), 0.0, 20.0)
    v["drag"] = _num(where, "drag", doc.get("drag", 0.0), 0.0, 100.0)
    # s: how far the autopilot's position/velocity estimate trails the vehicle (mppid's act-time prediction)
    v["estimate_lag"] = _num(where, "estimate_lag", doc.get("estimate_lag", 0.0), 0.0, 0.5)
    h = doc.get("hover_thrust")
    v["hover_thrust"] = None if h is None else _num(where, "hover_thrust", h, 0.01, 0.99)
    if v["model"] == "quadrotor_rate":
        v.update(_rate_model_fields(doc, where))
    elif v["model"] == "quadrotor":
        v.update(_motor_model_fields(doc, where))
    else:
        raise VehicleError(f"{where}: model: must be quadrotor_rate or quadrotor, got {v['model']!r}")
    v["params"] = _params(doc, where)
    return v


def _rate_model_fields(doc, where: str) -> dict:
    """quadrotor_rate's limits (required) and rate_response (defaults: tau 0.05, gain 1, delay 0)."""
    lim = doc.get("limits")
    if lim is None:
        raise VehicleError(f"{where}: limits: missing (max_thrust, max_body_rate)")
    _known(where, "limits", lim, {"max_thrust", "max_body_rate"})
    limits = {"max_thrust": _num(where, "limits.max_thrust", lim.get("max_thrust"), 1e-3, 1e6),
              "max_body_rate": _axes(where, "limits.max_body_rate", lim.get("max_body_rate"), 1e-3, 100.0)}
    rr = doc.get("rate_response") or {}
    _known(where, "rate_response", rr, {"tau", "gain", "delay"})
    return {"limits": limits,
            "rate_response": {"tau": _axes(where, "rate_response.tau", rr.get("tau", 0.05), 1e-3, 10.0),
                              "gain": _axes(where, "rate_response.gain", rr.get("gain", 1.0), 0.05, 20.0),
                              "delay": _num(where, "rate_response.delay", rr.get("delay", 0.0), 0.0, 1.0)}}


def _motor_model_fields(doc, where: str) -> dict:
    """quadrotor's limits (max_motor_speed, required); no rate_response."""
    lim = doc.get("limits")
    if doc.get("rate_response") is not None:
        raise VehicleError(f"{where}: rate_response: only for model quadrotor_rate")
    if lim is None:
        raise VehicleError(f"{where}: limits: missing (max_motor_speed)")
    _known(where, "limits", lim, {"max_motor_speed"})
    return {"limits": {"max_motor_speed": _num(where, "limits.max_motor_speed", lim.get("max_motor_speed"), 1.0, 1e6)}}


def _params(doc, where: str) -> dict:
    """params: name: number, none of them a field of the file's own (OWN_FIELDS, rate_*)."""
    params = doc.get("params") or {}
    if not isinstance(params, dict):
        raise VehicleError(f"{where}: params: expected a map of name: number")
    for k, x in params.items():
        if k in OWN_FIELDS or str(k).startswith("rate_"):
            raise VehicleError(f"{where}: params.{k}: has its own field in a vehicle file")
        _num(where, f"params.{k}", x, -1e12, 1e12)
    return dict(params)


def load(path: str | Path) -> dict:
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as e:
        raise VehicleError(f"vehicle file {p}: cannot open ({e.strerror})") from None
    except yaml.YAMLError as e:
        raise VehicleError(f"vehicle file {p}: {e}") from None
    v = parse(doc if doc is not None else {}, str(p))
    v["path"] = str(p)
    return v


def dump(v: dict, path: str | Path, header: str = ""):
    """Writes a vehicle file (tools/sysid): the fields of parse(), commented header first."""
    doc = {"description": v.get("description", ""), "name": v["name"], "model": v["model"], "mass": v["mass"],
           "gravity": v.get("gravity", 9.81), "hover_thrust": v.get("hover_thrust"), "drag": v.get("drag", 0.0),
           "limits": v["limits"]}
    if v["model"] == "quadrotor_rate":
        doc["rate_response"] = v["rate_response"]
    if v.get("estimate_lag"):
        doc["estimate_lag"] = v["estimate_lag"]
    if v.get("params"):
        doc["params"] = v["params"]
    parse(doc, str(path))  # what is written must read back
    text = "".join(f"# {line}\n" for line in header.splitlines()) + yaml.safe_dump(doc, sort_keys=False,
                                                                                  default_flow_style=None)
    Path(path).write_text(text)
