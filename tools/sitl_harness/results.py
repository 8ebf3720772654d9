"""A campaign's results (summary.json, written by campaign.py): the one reader every report
uses (compare, table, versus, autopilot-table, the robustness map, the campaign plot)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

SUMMARY = "summary.json"


@dataclass
class CampaignResults:
    folder: Path
    summary: dict        # the campaign's figures and how it was flown (`summary` of summary.json)
    runs: list[dict]     # one score per flight (score.json's), sorted by scenario and seed

    def scenarios(self) -> list[str]:
        """The scenarios of the runs, each once, in the runs' order."""
        return list(dict.fromkeys(r.get("scenario") for r in self.runs))

    def by_scenario(self) -> dict[str, list[dict]]:
        """{scenario: its runs}, scenarios in the runs' order."""
        out: dict[str, list[dict]] = {}
        for r in self.runs:
            out.setdefault(r.get("scenario"), []).append(r)
        return out

    def by_key(self) -> dict[tuple, dict]:
        """{(scenario, seed): run}."""
        return {(r.get("scenario"), r.get("seed")): r for r in self.runs}

    def flight_folder(self, scenario: str, seed: int) -> Path:
        return self.folder / scenario / f"seed_{seed:04d}"


def load_campaign(folder: Path) -> CampaignResults:
    """The results of a finished campaign; FileNotFoundError when it has no summary.json."""
    folder = Path(folder)
    f = folder / SUMMARY
    if not f.is_file():
        raise FileNotFoundError(f"{folder}: no {SUMMARY} (not a finished campaign)")
    data = json.loads(f.read_text())
    return CampaignResults(folder=folder, summary=data["summary"], runs=data["runs"])


def write_campaign(folder: Path, summary: dict, runs: list[dict]) -> Path:
    """summary.json: the summary and the runs sorted by scenario and seed."""
    f = Path(folder) / SUMMARY
    ordered = sorted(runs, key=lambda r: (r.get("scenario", ""), r.get("seed", 0)))
    f.write_text(json.dumps({"summary": summary, "runs": ordered}, indent=2))
    return f
