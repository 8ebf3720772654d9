"""`tools/sitl refusals` without an autopilot (sitl_harness/refusals.py, bad_missions.py): the
missions as each autopilot stores them and the tool's refusal of each, offline; the plan of
processes (a survey flight's, the ground station replaced); the STATUSTEXT chunks joined as the
bridge cuts them; the verdict and the table on recorded answers. The runs against the real
SITLs are bench/results/issue38_refusals."""
from __future__ import annotations

import json
import os

import pytest
import yaml

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink
from pymavlink import mavutil  # noqa: E402

from mppi_mavlink import notices  # noqa: E402
from mppi_mission import autopilot_plan  # noqa: E402
from sitl_helpers import fake_ardupilot  # noqa: E402
from test_px4_flight import _fake_px4  # noqa: E402
from sitl_harness import cli, refusals  # noqa: E402
from sitl_harness.bad_missions import BAD, FENCE, mission  # noqa: E402
from sitl_harness.flights.ardupilot import HOME  # noqa: E402

M = mavutil.mavlink
HOME_LLA = [float(v) for v in HOME.split(",")[:3]]
KEYS = ("seq", "frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z")


def _stored(items, dialect):
    """The items as the bridge reads them back from the autopilot: PX4 keeps DO_JUMP's repeat
    count in 16 bits (a -1 comes back 65535, PX4 SITL bb59c637cd)."""
    out = [{k: getattr(m, k) for k in KEYS} for m in items]
    for it in out:
        if dialect == "px4" and it["command"] == M.MAV_CMD_DO_JUMP:
            it["param2"] = float(int(it["param2"]) & 0xFFFF)
    return out


@pytest.mark.parametrize("dialect", ["ardupilot", "px4"])
def test_each_bad_mission_is_refused_naming_its_item_as_each_autopilot_stores_it(dialect):
    fence = {kv.split("=")[0][len("fence."):]: yaml.safe_load(kv.split("=", 1)[1]) for kv in FENCE}
    for bad in BAD:
        items = mission(dialect, HOME_LLA, *bad.rows) if bad.rows else []
        if items and dialect == "ardupilot":    # home, item 0, then the rows from 1
            assert (items[0].command, items[0].frame) == (M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_INT)
            assert [m.seq for m in items] == list(range(len(bad.rows) + 1))
        elif items:                             # PX4: from 0, the take-off where the vehicle stands
            assert [m.seq for m in items] == list(range(len(bad.rows))) and items[0].command == M.MAV_CMD_NAV_TAKEOFF
            assert (items[0].x, items[0].y) == (round(HOME_LLA[0] * 1e7), round(HOME_LLA[1] * 1e7))
        dl = {"dialect": dialect, "items": _stored(items, dialect), "home": HOME_LLA, "origin": HOME_LLA,
              "fence": fence, "current": 0}
        with pytest.raises(autopilot_plan.Refusal) as e:
            autopilot_plan.convert(dl, here=[0.0, 0.0, 0.0])
        assert e.value.number == bad.number, (bad.name, str(e.value))
        assert any(r in str(e.value) for r in bad.reason), (bad.name, str(e.value))
    jump = next(m for m in mission(dialect, HOME_LLA, *BAD[3].rows) if m.command == M.MAV_CMD_DO_JUMP)
    assert jump.param1 == (2 if dialect == "ardupilot" else 1)         # item 2 in the dialect's numbering


def test_the_processes_are_the_survey_flights(mppid_binary, tmp_path):
    ap = refusals.plan("ardupilot", tmp_path / "ap", str(fake_ardupilot(tmp_path)))
    px4 = refusals.plan("px4", tmp_path / "px4", str(_fake_px4(tmp_path)))
    for p in (ap, px4):
        assert set(p["commands"]) == {"sim", "controller", "bridge", "gcs"}
        assert p["commands"]["controller"][0] == str(mppid_binary)
        assert p["commands"]["bridge"][-6:] == ["--set", FENCE[0], "--set", FENCE[1], "--set", FENCE[2]]
        assert p["commands"]["gcs"][1:] == ["-m", "sitl_harness.refusals", p["tool"][p["tool"].index("--out") + 1]
                                            + "/plan.json"]
        assert p["tool"][1:4] == ["-m", "mppi_mission", "from-autopilot"]
    assert (ap["url"], ap["dialect"], ap["home"]) == ("tcp:127.0.0.1:5763", "ardupilot", HOME_LLA)
    assert (px4["url"], px4["dialect"], px4["home"]) == ("udpin:127.0.0.1:14550", "px4", None)
    assert "config/bridge/px4_sitl.yaml" in " ".join(px4["commands"]["bridge"])
    assert refusals.tool_command(ap["tool"], tmp_path / "x")[ap["tool"].index("--out") + 1] == str(tmp_path / "x")


def test_the_refusal_is_read_whole_as_the_bridge_cuts_it():
    text = "mppid refuses the mission: mission item 3: NAV_LOITER_UNLIM: mppid cannot fly it (it flies NAV_TAKEOFF)"
    pieces = [p.decode() for p in notices.chunks(text)]
    assert len(pieces) == 3
    ch = refusals.Chunks()
    assert [ch.add((1, 191), 7, i, p) for i, p in enumerate(pieces)] == [None, None, text]
    assert ch.add((1, 1), 0, 0, "Flight plan received") == "Flight plan received"
    assert ch.parts == {}


def _answer(**kw):
    """One mission's answer as the ground station records it (ArduCopter's, trimmed)."""
    hb = {"armed": False, "mode": "STABILIZE", "wall": 1.0}
    a = {"ack": 0, "exit": 1, "before": hb, "heartbeats": [hb, {**hb, "wall": 2.0}], "tool_said": [],
         "statustexts": [{"src": 1, "severity": 6, "text": "Flight plan received", "wall": 1.5},
                         {"src": 191, "severity": 2, "wall": 1.6,
                          "text": "mppid refuses the mission: mission item 3: NAV_LOITER_UNLIM: mppid cannot fly it"}]}
    return {**a, **kw}


@pytest.mark.parametrize("change, why", [
    ({}, ""),
    ({"exit": 0}, "exit 0"),
    ({"ack": M.MAV_MISSION_UNSUPPORTED}, "upload answered 3"),
    ({"statustexts": []}, "no refusal on the ground station"),
    ({"heartbeats": [{"armed": True, "mode": "GUIDED", "wall": 2.0}]}, "armed; mode STABILIZE -> ['GUIDED']"),
    ({"heartbeats": []}, "no heartbeat after the tool"),
    ({"statustexts": [{"src": 191, "severity": 2, "wall": 1.6,
                       "text": "mppid refuses the mission: mission item 2: NAV_LOITER_UNLIM: mppid cannot fly it"}]},
     "item 2, not 3"),
    ({"statustexts": [{"src": 191, "severity": 2, "wall": 1.6,
                       "text": "mppid refuses the mission: mission item 3: DO_JUMP to item 9: no such item"}]},
     "not the reason expected"),
])
def test_the_verdict_on_recorded_answers(change, why):
    row = refusals.verdict(BAD[0], _answer(**change))
    assert row["pass"] == (why == "") and row["why"] == why, row
    if not why:
        assert (row["item"], row["reason"], row["mode_before"], row["mode_after"]) == \
            (3, "NAV_LOITER_UNLIM: mppid cannot fly it", "STABILIZE", "STABILIZE")


def test_the_table_and_refusals_json(tmp_path):
    empty = _answer(statustexts=[{"src": 191, "severity": 2, "wall": 1.6, "text": "mppid refuses the mission: "
                                  "mission: the autopilot's mission is empty: plan one"}])
    answers = {"unflyable": _answer(), "empty": empty}
    binary = fake_ardupilot(tmp_path)
    rows, ok = refusals.report({"autopilot": "ardupilot", "binary": str(binary)}, answers, tmp_path)
    assert not ok and [r["pass"] for r in rows] == [True, False, False, False, True]
    assert rows[1]["why"] == "not tried"
    doc = json.loads((tmp_path / "refusals.json").read_text())
    assert doc["all_refused"] is False and doc["answers"] == answers and len(doc["missions"]) == len(BAD)
    assert (doc["binary"], doc["autopilot_commit"]) == ("build/sitl/bin/arducopter", None)   # not a checkout
    lines = refusals.table(rows).splitlines()
    assert lines[0].startswith("| mission | item | reason said | exit | armed? | mode before / after | pass |")
    assert lines[2] == ("| unflyable: a command mppid does not fly (NAV_LOITER_UNLIM) | 3 | NAV_LOITER_UNLIM: mppid "
                        "cannot fly it | 1 | no | STABILIZE / STABILIZE | yes |")
    assert lines[3].endswith("| NO: not tried |") and lines[-1].split(" | ")[1] == "-"   # the empty one: no item


def test_a_missing_autopilot_binary_is_a_usage_error(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("MPPID_PX4_BIN", raising=False)
    assert cli.main(["refusals", "--autopilot", "px4", "--out", str(tmp_path)]) == 2
    assert "sitl: no PX4 SITL binary" in capsys.readouterr().err
