"""mppid-realsense's settings: a YAML file (config/realsense/realsense.yaml) and --set overrides,
checked field by field. A bad value raises SettingsError naming the field (the program exits 2)."""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import yaml

DEFAULTS = {
    "device": {"serial": ""},
    "stream": {"width": 848, "height": 480, "fps": 30},
    "decimation": 4,
    "range": {"min": 0.2, "max": 10.0},
    "max_points": 20000,
    "mount": {"offset": [0.1, 0.0, 0.0], "rotation_deg": [0.0, 0.0, 0.0]},
    "timestamps": "camera",
    "state": {"channel": "MPPI_STATE", "vehicle": 0, "max_age": 0.1},
    "channel": "MPPI_DEPTH",
    "lcm_url": "",
    "sensor_lcm_url": "",
}


class SettingsError(ValueError):
    """A settings file or override that cannot run; the message names the field."""


@dataclass(frozen=True)
class Settings:
    serial: str
    width: int
    height: int
    fps: int
    decimation: int
    min_range: float
    max_range: float
    max_points: int
    mount_offset: tuple
    mount_rotation_deg: tuple
    timestamps: str
    state_channel: str
    vehicle: int
    max_state_age: float
    channel: str
    lcm_url: str
    sensor_lcm_url: str


def _merge(base: dict, over: dict, where: str = "") -> None:
    for key, value in over.items():
        name = f"{where}{key}"
        if key not in base:
            raise SettingsError(f"{name}: unknown setting")
        if isinstance(base[key], dict):
            if not isinstance(value, dict):
                raise SettingsError(f"{name}: must be a mapping")
            _merge(base[key], value, name + ".")
        else:
            base[key] = value


def _set(tree: dict, assignment: str) -> None:
    """One --set key.sub=value (the value read as YAML)."""
    key, eq, text = assignment.partition("=")
    if not eq or not key:
        raise SettingsError(f"--set {assignment!r}: expected key=value")
    over: dict = {}
    node = over
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = yaml.safe_load(text)
    _merge(tree, over)


def _int(tree: dict, name: str, lo: int, hi: int) -> int:
    v = _get(tree, name)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise SettingsError(f"{name}: must be an integer in [{lo}, {hi}], got {v!r}")
    return v


def _float(tree: dict, name: str, lo: float, hi: float) -> float:
    v = _get(tree, name)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise SettingsError(f"{name}: must be a number in [{lo}, {hi}], got {v!r}")
    return float(v)


def _str(tree: dict, name: str, choices: tuple = ()) -> str:
    v = _get(tree, name)
    if not isinstance(v, str) or (choices and v not in choices):
        want = f"one of {', '.join(choices)}" if choices else "a string"
        raise SettingsError(f"{name}: must be {want}, got {v!r}")
    return v


def _vec3(tree: dict, name: str, bound: float) -> tuple:
    v = _get(tree, name)
    ok = isinstance(v, list) and len(v) == 3 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and abs(x) <= bound for x in v)
    if not ok:
        raise SettingsError(f"{name}: must be three numbers within +-{bound}, got {v!r}")
    return tuple(float(x) for x in v)


def _get(tree: dict, name: str):
    node = tree
    for p in name.split("."):
        node = node[p]
    return node


def parse(tree: dict) -> Settings:
    s = Settings(
        serial=str(_get(tree, "device.serial") or ""),
        width=_int(tree, "stream.width", 16, 4096),
        height=_int(tree, "stream.height", 16, 4096),
        fps=_int(tree, "stream.fps", 1, 300),
        decimation=_int(tree, "decimation", 1, 8),
        min_range=_float(tree, "range.min", 0.0, 100.0),
        max_range=_float(tree, "range.max", 0.01, 100.0),
        max_points=_int(tree, "max_points", 1, 10_000_000),
        mount_offset=_vec3(tree, "mount.offset", 10.0),
        mount_rotation_deg=_vec3(tree, "mount.rotation_deg", 360.0),
        timestamps=_str(tree, "timestamps", ("camera", "host")),
        state_channel=_str(tree, "state.channel"),
        vehicle=_int(tree, "state.vehicle", 0, 255),
        max_state_age=_float(tree, "state.max_age", 1e-3, 60.0),
        channel=_str(tree, "channel"),
        lcm_url=_str(tree, "lcm_url"),
        sensor_lcm_url=_str(tree, "sensor_lcm_url"),
    )
    if s.min_range >= s.max_range:
        raise SettingsError(f"range.min: must be below range.max ({s.max_range}), got {s.min_range}")
    for name, v in (("state.channel", s.state_channel), ("channel", s.channel)):
        if not v:
            raise SettingsError(f"{name}: must not be empty")
    return s


def load(path: str | None, overrides: list[str] = ()) -> Settings:
    """The defaults, then the file at `path` (if any), then each key=value of `overrides`."""
    tree = copy.deepcopy(DEFAULTS)
    if path:
        try:
            doc = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as e:
            raise SettingsError(f"{path}: {e}") from e
        if doc is not None:
            if not isinstance(doc, dict):
                raise SettingsError(f"{path}: must be a mapping of settings")
            _merge(tree, doc)
    for assignment in overrides:
        _set(tree, assignment)
    return parse(tree)
