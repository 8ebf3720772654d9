"""Settings overlays: a YAML file in the shape of a settings file (config/tasks/*.yaml) that
holds only the keys it changes, e.g. what `tools/sitl tune` writes:

    mppi:
      lambda: 37.5
      sigma: [2.5, 1.2, 1.2, 0.6]
    cost:
      w_obstacle: 1200.0

It becomes the daemon's `--set key.path=value` pairs (`tools/sitl run|campaign --overlay
FILE`; `tools/sitl overlay FILE` prints them for `mppid --config ... $(...)`), or is merged
into a whole settings file (`merge_config`) that `mppid --config` reads as it is.
"""
from __future__ import annotations

import math
from pathlib import Path

import yaml


class OverlayError(ValueError):
    pass


def _value_text(v, key: str) -> str:
    """A value as YAML flow text without spaces (one shell word)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and not math.isfinite(v):
            raise OverlayError(f"{key}: must be finite")
        if isinstance(v, int):
            return str(v)
        text = repr(v)
        mant, e, exp = text.partition("e")
        if e and "." not in mant:
            text = f"{mant}.0e{exp}"  # 1.0e-05: a float for YAML 1.1 (PyYAML) and 1.2 alike
        return text
    if isinstance(v, str):
        if not v or any(c in v for c in " \t\n:#[]{},'\""):
            raise OverlayError(f"{key}: string value {v!r} is not a plain word")
        return v
    if isinstance(v, list):
        return "[" + ",".join(_value_text(x, f"{key}[{i}]") for i, x in enumerate(v)) + "]"
    raise OverlayError(f"{key}: expected a number, a word or a list, got {type(v).__name__}")


def to_sets(doc, prefix: str = "") -> list[str]:
    """Nested map -> ["a.b=value", ...] in file order."""
    if not isinstance(doc, dict):
        raise OverlayError(f"{prefix or '(file)'}: expected a map")
    out = []
    for k, v in doc.items():
        if not isinstance(k, str) or not k or "." in k or "=" in k:
            raise OverlayError(f"{prefix}{k!r}: not a settings key")
        key = prefix + k
        if isinstance(v, dict):
            out += to_sets(v, key + ".")
        elif v is None:
            raise OverlayError(f"{key}: no value")
        else:
            out.append(f"{key}={_value_text(v, key)}")
    return out


def load_sets(path) -> list[str]:
    """The --set pairs of an overlay file; OverlayError naming the file and key."""
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as e:
        raise OverlayError(f"overlay {p}: {e.strerror or e}") from e
    except yaml.YAMLError as e:
        raise OverlayError(f"overlay {p}: not valid YAML: {e}") from e
    if doc is None:
        return []
    try:
        return to_sets(doc)
    except OverlayError as e:
        raise OverlayError(f"overlay {p}: {e}") from e


def from_sets(sets) -> dict:
    """["a.b=1.5", ...] -> {"a": {"b": 1.5}} (values parsed as YAML)."""
    doc: dict = {}
    for kv in sets:
        key, eq, val = kv.partition("=")
        if not eq:
            raise OverlayError(f"{kv}: expected key.path=value")
        parts = key.split(".")
        node = doc
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise OverlayError(f"{key}: '{part}' is both a value and a section")
        node[parts[-1]] = yaml.safe_load(val)
    return doc


def merge_config(config_path, sets) -> dict:
    """A whole settings file with the --set pairs applied (as mppid applies --set)."""
    doc = yaml.safe_load(Path(config_path).read_text()) or {}
    for kv in sets:
        key, _, val = kv.partition("=")
        parts = key.split(".")
        node = doc
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                node[part] = {}
            node = node[part]
        node[parts[-1]] = yaml.safe_load(val)
    return doc
