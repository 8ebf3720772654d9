"""tools/sysid (docs/sysid.md): the fit on a synthetic log of the model's own equations, and on
mppid-sim, where the truth is known: the identification manoeuvre flown through the daemon
(daemon.identify) and fitted recovers the plant's rate response, mass and delay within 5 %,
a fast circle its drag, and the vehicle file written flies in mppid. Lock-step with a fixed
charged latency, so each flight repeats (about 5 s each on the 2-core VM)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from sitl_helpers import ROOT, sitl

sys.path.insert(0, str(ROOT / "tools"))
sys.path.insert(0, str(ROOT / "drivers" / "mavlink"))

from sysid_fit import fit as sysid_fit  # noqa: E402
from sysid_fit.logs import FlightData  # noqa: E402
from sysid_fit.model import RateModel, predict  # noqa: E402

SYSID = ROOT / "tools" / "sysid"
SCENARIO = ROOT / "config" / "scenarios" / "rate_identify.yaml"
LATENCY = 0.004


def sysid(*args, check=0):
    p = subprocess.run([str(SYSID), *map(str, args)], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert p.returncode == check, f"rc={p.returncode}\nstdout:\n{p.stdout}\nstderr:\n{p.stderr}"
    return p


def synthetic_flight(truth: RateModel, seconds=12.0, seed=3, yaw=True) -> FlightData:
    """The numpy model flies random rate steps and thrust around hover, commands at 50 Hz
    from a random phase, states at 50 Hz with a little noise (yaw=False: no yaw command)."""
    rng = np.random.default_rng(seed)
    tc = 0.007 + 0.02 * np.arange(int(seconds / 0.02))
    u = np.zeros((len(tc), 4))
    u[:, 0] = truth.mass * 9.81 * (1.0 + 0.15 * np.repeat(rng.uniform(-1, 1, len(tc) // 10 + 1), 10)[:len(tc)])
    for a in range(3):
        u[:, 1 + a] = np.repeat(rng.uniform(-1.5, 1.5, len(tc) // 8 + 1), 8)[:len(tc)]
    u[:, 3] *= float(yaw)
    t = 0.02 * np.arange(int(seconds / 0.02) - 1)
    x = np.zeros((len(t), 13))
    x[0, 2], x[0, 6] = 5.0, 1.0
    for k in range(1, len(t)):
        x[k] = predict(truth, x[k - 1:k], t[k - 1:k], 0.02, tc, u, h=0.001)[0]
    noisy = x + rng.normal(0.0, 1.0, x.shape) * np.r_[[0.002] * 3, [0.005] * 3, [0.0] * 4, [0.005] * 3]
    return FlightData(t, noisy, tc, u, "synthetic", "realtime")


def test_the_fit_recovers_the_equations_it_fits():
    truth = RateModel(mass=1.4, drag=0.0, tau=[0.04, 0.07, 0.12], gain=[1.2, 0.85, 0.7], delay=0.023)
    data = synthetic_flight(truth)
    grid = sysid_fit.Grid(data)
    delay, axes = sysid_fit.fit_common_delay(data, grid)
    assert delay == pytest.approx(truth.delay, abs=0.0005)
    for a in range(3):
        assert axes[a].tau == pytest.approx(truth.tau[a], rel=0.02)
        assert axes[a].gain == pytest.approx(truth.gain[a], rel=0.02)
    thrust = sysid_fit.fit_thrust(data, grid, delay)
    assert thrust.mass == pytest.approx(truth.mass, rel=0.01)


def truth_of(report: dict) -> dict:
    return {k: v["error_pct"] for k, v in report["truth"].items()}


def fly_and_fit(tmp_path: Path, scenario: Path, *extra) -> dict:
    out = tmp_path / "flight"
    sitl("run", "--scenario", scenario, "--latency", LATENCY, "--out", out, "--no-plots", "--quiet",
         "--set", "mppi.rollouts=1024", "--set", "mppi.threads=1", *extra, check=0)
    assert json.loads((out / "score.json").read_text())["success"]
    sysid("fit", out / "flight.lcmlog", "--lockstep-latency", LATENCY, "--truth", scenario,
          "--out", tmp_path / "fitted.yaml", "--report", tmp_path / "fit.json")
    return json.loads((tmp_path / "fit.json").read_text())


def test_the_identification_manoeuvre_in_sim_gives_the_plant_within_5_percent(tmp_path, mppid_binary):
    report = fly_and_fit(tmp_path, SCENARIO, "--param", "1:daemon.identify=1")
    errors = truth_of(report)
    for key in ("mass", "delay", "tau_x", "tau_y", "tau_z", "gain_x", "gain_y", "gain_z"):
        assert abs(errors[key]) < 5.0, f"{key}: {errors[key]:+.1f} % ({report['truth'][key]})"
    held = report["held_out"]
    # The fitted model predicts the held-out flight 0.5 s ahead far better than the prior.
    assert held["fitted"]["position_m"] < 0.2 * held["prior"]["position_m"]
    assert held["fitted"]["rate_rad_s"] < 0.2 * held["prior"]["rate_rad_s"]
    # The vehicle file it wrote is one mppid flies: the task's hover becomes its mass x g.
    fitted = yaml.safe_load((tmp_path / "fitted.yaml").read_text())
    assert fitted["mass"] == pytest.approx(1.25, rel=0.05)
    p = subprocess.run([str(mppid_binary), "--config", ROOT / "config/tasks/quadrotor_rate_track.yaml",
                        "--vehicle", tmp_path / "fitted.yaml", "--lcm-url", "memq://", "--duration", "0.2"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert "vehicle sim_rate_1kg_sysid" in p.stderr + p.stdout


def test_drag_comes_from_a_flight_with_speed(tmp_path, mppid_binary):
    # The manoeuvre stays inside its 1.5 m box, where drag barely shows (8-13 % off); a
    # circle at 5 m/s with the same plant gives it.
    doc = yaml.safe_load(SCENARIO.read_text())
    circle = yaml.safe_load((ROOT / "config/scenarios/rate_track_circle_fast.yaml").read_text())
    circle.update(name="rate_identify_circle", plant=doc["plant"], noise=doc["noise"])
    circle["timing"]["actuation_delay"] = doc["timing"]["actuation_delay"]
    circle["timing"]["duration"] = 12
    path = tmp_path / "circle.yaml"
    path.write_text(yaml.safe_dump(circle))
    errors = truth_of(fly_and_fit(tmp_path, path))
    assert abs(errors["drag"]) < 5.0
    assert abs(errors["mass"]) < 5.0


def test_a_log_without_rate_model_states_is_refused(tmp_path):
    import lcm

    log = lcm.EventLog(str(tmp_path / "empty.lcmlog"), "w", overwrite=True)
    log.write_event(0, "MPPI_STATE", b"not a state")
    log.close()
    p = sysid("fit", tmp_path / "empty.lcmlog", check=1)
    assert "too few to fit" in p.stderr



# ---- through the bridge: only the engaged flight ---------------------------------------------

T0_US = 1_700_000_000_000_000


def write_lcm_flight(path: Path, data: FlightData, commands: np.ndarray, link: list[tuple[float, bool]] = ()):
    """An LCM log as a flight through the bridge records it: the states, `commands` (as mppid
    sent them, at data.tc) and the bridge's link messages (time [s], engaged)."""
    import lcm
    from mppi_mavlink import lcm_types

    lcm_types.import_mppi_lcm()
    from mppi_lcm import command_t, vehicle_state_t
    link_t = lcm_types.import_link_type()
    events = []
    for k, (t, x) in enumerate(zip(data.t, data.x)):
        m = vehicle_state_t()
        m.utime = m.sample_utime = T0_US + int(round(t * 1e6))
        m.seq, m.model, m.vehicle_count, m.nx, m.n, m.x = k, 2, 1, 13, 13, list(map(float, x))
        events.append((m.utime, "MPPI_STATE", m.encode()))
    for k, (t, u) in enumerate(zip(data.tc, commands)):
        m = command_t()
        m.utime, m.seq, m.state_seq, m.mode, m.kind = T0_US + int(round(t * 1e6)), k, k, 0, 2
        m.n, m.u = 4, list(map(float, u))
        events.append((m.utime, "MPPI_COMMAND", m.encode()))
    for k, (t, engaged, *mode) in enumerate(link):   # (t, engaged) on ArduPilot, (t, engaged, mode) on PX4
        m = link_t()
        m.utime, m.seq, m.engaged, m.hover_thrust = T0_US + int(round(t * 1e6)), k, int(engaged), -1.0
        m.dialect, m.mode = ("px4", mode[0]) if mode else ("ardupilot", "GUIDED")
        m.hover_source, m.error = "", ""
        events.append((m.utime, "MPPI_MAVLINK_LINK", m.encode()))
    log = lcm.EventLog(str(path), "w", overwrite=True)
    for utime, channel, msg in sorted(events, key=lambda e: e[0]):
        log.write_event(utime, channel, msg)
    log.close()


def test_only_the_flight_the_bridge_was_engaged_for_is_fitted(tmp_path):
    # ArduCopter's own takeoff (0-4 s) and landing (20-24 s): the vehicle flies its own
    # commands while mppid's, logged, go nowhere. Engaged in between, it follows mppid's.
    truth = RateModel(mass=1.2, drag=0.0, tau=[0.06, 0.08, 0.12], gain=[1.1, 0.9, 0.8], delay=0.02)
    data = synthetic_flight(truth, seconds=24.0, seed=7)
    sent = data.u.copy()
    outside = (data.tc < 4.0) | (data.tc >= 20.0)
    sent[outside, 0] *= 1.3
    sent[outside, 1:] = np.random.default_rng(8).uniform(-1.5, 1.5, (int(outside.sum()), 3))
    link = [(t, 4.0 <= t < 20.0) for t in np.arange(0.0, 24.0, 0.5)] + [(4.0, True), (20.0, False)]
    write_lcm_flight(tmp_path / "bridge.lcmlog", data, sent, link)
    p = sysid("fit", tmp_path / "bridge.lcmlog", "--report", tmp_path / "fit.json")
    assert "bridge engaged 16.0 s" in p.stdout
    report = json.loads((tmp_path / "fit.json").read_text())
    assert report["engaged_s"] == pytest.approx(16.0, abs=0.05)
    assert report["fit_s"] == pytest.approx(11.2, abs=0.05)
    fit = report["fit"]
    assert fit["delay_s"] == pytest.approx(truth.delay, abs=0.001)
    assert fit["mass_kg"] == pytest.approx(truth.mass, rel=0.02)
    for i, ax in enumerate("xyz"):
        assert fit["axes"][ax]["gain"] == pytest.approx(truth.gain[i], rel=0.03)
        assert fit["axes"][ax]["tau_s"] == pytest.approx(truth.tau[i], rel=0.03)
    held = report["held_out"]
    assert held["fitted"]["position_m"] < 0.2 * held["prior"]["position_m"]
    # The same flight without the link messages: fitted over all of it, as before.
    write_lcm_flight(tmp_path / "nolink.lcmlog", data, sent)
    sysid("fit", tmp_path / "nolink.lcmlog", "--report", tmp_path / "nolink.json")
    whole = json.loads((tmp_path / "nolink.json").read_text())
    assert whole["engaged_s"] is None and whole["fit_s"] > 16.0
    off = [abs(whole["fit"]["axes"][ax]["gain"] / truth.gain[i] - 1.0) for i, ax in enumerate("xyz")]
    assert max(off) > 0.05, off   # the unfollowed commands bias it


def test_px4s_pre_stream_is_not_fitted(tmp_path):
    """On PX4 the bridge's `engaged` covers its pre-stream too (mppid's setpoints reach PX4,
    which flies its own take-off and landing meanwhile): only OFFBOARD counts."""
    truth = RateModel(mass=1.0, drag=0.0, tau=[0.1, 0.12, 0.12], gain=[1.1, 1.0, 0.8], delay=0.024)
    data = synthetic_flight(truth, seconds=24.0, seed=11)
    sent = data.u.copy()
    outside = (data.tc < 4.0) | (data.tc >= 20.0)
    sent[outside, 1:] = np.random.default_rng(12).uniform(-1.5, 1.5, (int(outside.sum()), 3))
    link = [(t, True, "OFFBOARD" if 4.0 <= t < 20.0 else "TAKEOFF" if t < 4.0 else "LAND")
            for t in np.arange(0.0, 24.0, 0.5)]
    write_lcm_flight(tmp_path / "px4.lcmlog", data, sent, link)
    p = sysid("fit", tmp_path / "px4.lcmlog", "--report", tmp_path / "fit.json")
    assert "bridge engaged 16.0 s" in p.stdout
    fit = json.loads((tmp_path / "fit.json").read_text())["fit"]
    for i, ax in enumerate("xyz"):
        assert fit["axes"][ax]["gain"] == pytest.approx(truth.gain[i], rel=0.03)


def test_an_axis_the_flight_did_not_excite_keeps_the_prior(tmp_path):
    truth = RateModel(mass=1.0, tau=[0.06, 0.08, 0.3], gain=[1.1, 0.9, 0.5], delay=0.01)
    data = synthetic_flight(truth, seconds=10.0, seed=9, yaw=False)
    assert sysid_fit.excited_axes(data) == [0, 1]
    write_lcm_flight(tmp_path / "noyaw.lcmlog", data, data.u)
    sysid("fit", tmp_path / "noyaw.lcmlog", "--report", tmp_path / "fit.json")
    fit = json.loads((tmp_path / "fit.json").read_text())["fit"]
    assert fit["kept_prior"] == ["z"]
    prior = yaml.safe_load((ROOT / "config/vehicles/sim_rate_1kg.yaml").read_text())["rate_response"]
    assert (fit["axes"]["z"]["gain"], fit["axes"]["z"]["tau_s"]) == (prior["gain"][2], prior["tau"][2])
    for i, ax in enumerate("xy"):
        assert fit["axes"][ax]["gain"] == pytest.approx(truth.gain[i], rel=0.03)
    # --keep-prior holds an excited axis too.
    sysid("fit", tmp_path / "noyaw.lcmlog", "--keep-prior", "x", "--report", tmp_path / "keep.json")
    assert json.loads((tmp_path / "keep.json").read_text())["fit"]["kept_prior"] == ["x", "z"]


# ---- ArduPilot dataflash ----------------------------------------------------------------------

def write_dataflash(path: Path, messages: dict):
    """A dataflash log as ArduPilot writes it (0xA3 0x95 header, FMT records first): for each
    name, (type id, format, columns, rows of values), the rows interleaved by time (first value)."""
    import struct

    from pymavlink import DFReader

    out = bytearray()
    fmt_len = 3 + struct.calcsize("<BB4s16s64s")
    out += bytes([0xA3, 0x95, 128]) + struct.pack("<BB4s16s64s", 128, fmt_len, b"FMT", b"BBnNZ",
                                                  b"Type,Length,Name,Format,Columns")
    packers = {}
    for name, (tid, fmt, cols, _) in messages.items():
        st = "<" + "".join(DFReader.FORMAT_TO_STRUCT[c][0] for c in fmt)
        packers[name] = (tid, struct.Struct(st))
        out += bytes([0xA3, 0x95, 128]) + struct.pack("<BB4s16s64s", tid, 3 + struct.calcsize(st), name.encode(),
                                                      fmt.encode(), cols.encode())
    records = sorted((row[0], name, row) for name, (_, _, _, rows) in messages.items() for row in rows)
    for _, name, row in records:
        tid, st = packers[name]
        out += bytes([0xA3, 0x95, tid]) + st.pack(*row)
    path.write_bytes(bytes(out))


def euler_ned(q):
    """ZYX roll, pitch, yaw [rad] of a NED/FRD quaternion (w, x, y, z)."""
    w, x, y, z = q
    return (np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)), np.arcsin(np.clip(2 * (w * y - z * x), -1, 1)),
            np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def test_an_ardupilot_dataflash_log_reads_as_the_same_flight(tmp_path):
    from mppi_mavlink import frames
    from sysid_fit.logs import read_dataflash

    truth = RateModel(mass=1.0, tau=[0.05, 0.06, 0.09], gain=[1.1, 0.9, 0.8], delay=0.012)
    data = synthetic_flight(truth, seconds=10.0, seed=5)
    hover, deg = 0.4, 180.0 / np.pi
    us = lambda t: int(round(t * 1e6)) + 1000000  # noqa: E731
    rate, att, ekf, ctun = [], [], [], []
    for t, x in zip(data.t, data.x):
        r, p, y = euler_ned(frames.q_enu_flu_to_ned_frd(tuple(x[6:10])))
        rate.append((us(t), 0.0, x[10] * deg, 0.0, -x[11] * deg, 0.0, -x[12] * deg))
        att.append((us(t), r * deg, p * deg, y * deg))
        ekf.append((us(t), 0, x[1], x[0], -x[2], x[4], x[3], -x[5]))
        ctun.append((us(t), 0.5, hover))
    guia = [(us(t), 1, 0.0, 0.0, 0.0, u[1] * deg, -u[2] * deg, -u[3] * deg, u[0] * hover / 9.81, 0.0)
            for t, u in zip(data.tc, data.u)]
    write_dataflash(tmp_path / "flight.BIN", {
        "RATE": (129, "Qffffff", "TimeUS,RDes,R,PDes,P,YDes,Y", rate),
        "ATT": (130, "Qfff", "TimeUS,Roll,Pitch,Yaw", att),
        "XKF1": (131, "QBffffff", "TimeUS,C,PN,PE,PD,VN,VE,VD", ekf),
        "CTUN": (132, "Qff", "TimeUS,ThO,ThH", ctun),
        "GUIA": (133, "QBffffffff", "TimeUS,Type,Roll,Pitch,Yaw,RollRt,PitchRt,YawRt,Thrust,ClimbRt", guia)})
    back = read_dataflash(tmp_path / "flight.BIN", mass=1.0, gravity=9.81, hover_throttle=None)
    assert back.hover_thrust == pytest.approx(hover)
    np.testing.assert_allclose(back.x[:, 0:6], data.x[:, 0:6], atol=2e-3)
    np.testing.assert_allclose(np.abs(np.sum(back.x[:, 6:10] * data.x[:, 6:10], axis=1)), 1.0, atol=1e-5)
    np.testing.assert_allclose(back.x[:, 10:13], data.x[:, 10:13], atol=1e-5)
    np.testing.assert_allclose(back.u, data.u, rtol=1e-5, atol=1e-5)
    grid = sysid_fit.Grid(back)
    delay, axes = sysid_fit.fit_common_delay(back, grid)
    assert delay == pytest.approx(truth.delay, abs=0.0005)
    for a in range(3):
        assert axes[a].gain == pytest.approx(truth.gain[a], rel=0.02)


def test_ulog_offboard_intervals_and_hover():
    """PX4's ULog: only OFFBOARD (vehicle_status.nav_state 14) is fitted; the hover throttle is
    the vehicle file's, else PX4's estimate while valid, else MPC_THR_HOVER."""
    from sysid_fit import logs
    status = {"timestamp": np.array([0.0, 1e6, 2e6, 5e6, 6e6, 9e6]), "nav_state": np.array([4, 17, 14, 4, 14, 14])}
    assert logs._offboard_spans(status) == [(2e6, 5e6), (6e6, 9e6)]
    assert logs._offboard_spans(None) is None
    est = {"hover_thrust": np.full(20, 0.47), "valid": np.ones(20)}
    assert logs._ulog_hover({"hover_thrust_estimate": est}, {"MPC_THR_HOVER": 0.5}, None) == pytest.approx(0.47)
    assert logs._ulog_hover({}, {"MPC_THR_HOVER": 0.42}, None) == pytest.approx(0.42)
    assert logs._ulog_hover({"hover_thrust_estimate": est}, {}, 0.6) == 0.6
