"""Where things are: the repository, the build outputs, the scenarios."""
from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"
MISSIONS = ROOT / "config" / "missions"   # what the mission tool flies; the scenarios of --autopilot ardupilot
TASKS = ROOT / "config" / "tasks"
VENV_BIN = ROOT / ".venv" / "bin"


def build_dirs() -> list[Path]:
    """Build folders searched for binaries, in order: $MPPID_BUILD_DIR, build, build-sim."""
    dirs = []
    env = os.environ.get("MPPID_BUILD_DIR")
    if env:
        dirs.append(Path(env).resolve())
    dirs += [ROOT / "build", ROOT / "build-sim"]
    return dirs


def find_binary(name: str) -> Path | None:
    for d in build_dirs():
        p = d / "bin" / name
        if p.is_file() and os.access(p, os.X_OK):
            return p
    return None


def require_lcm_types() -> None:
    """Checks that the LCM types (`mppi_lcm`, installed with the project's Python packages)
    import; RuntimeError saying how to get them otherwise."""
    import importlib.util

    if importlib.util.find_spec("mppi_lcm") is None:
        raise RuntimeError("mppi_lcm Python types not importable: install the project's Python packages "
                           "(tools/setup.sh)")


def scenario_path(name: str) -> Path:
    """A YAML file, a scenario name (config/scenarios) or a mission name (config/missions)."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") and p.is_file():
        return p.resolve()
    for folder in (SCENARIOS, MISSIONS):
        if (folder / f"{name}.yaml").is_file():
            return folder / f"{name}.yaml"
    raise FileNotFoundError(f"no scenario or mission '{name}' in {SCENARIOS} or {MISSIONS}")


def scenario_label(name: str) -> str:
    """What a scenario is called in results (campaign folders, score.json, summaries): its
    `name` key, else the file's stem. `name` is a repository scenario name or a YAML file."""
    import yaml

    p = scenario_path(name)
    try:
        doc = yaml.safe_load(p.read_text()) or {}
    except (OSError, yaml.YAMLError) as e:
        raise FileNotFoundError(f"scenario {name}: cannot read {p}: {e}") from e
    label = doc.get("name") if isinstance(doc, dict) else None
    label = str(label) if label else p.stem
    if not label or "/" in label or label in (".", ".."):
        raise FileNotFoundError(f"scenario {name}: name '{label}' cannot name a folder")
    return label


def scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIOS.glob("*.yaml"))


def mission_names() -> list[str]:
    return sorted(p.stem for p in MISSIONS.glob("*.yaml"))
