"""The vehicle file on the bridge's side (drivers/mavlink/mppi_mavlink/vehicle.py): the thrust
map's mass, gravity and hover thrust come from the file mppid flies; a different value in
the bridge's settings is refused naming both; and the bridge's reader and mppid's accept and
refuse the same files. No processes but short mppid runs on memq://."""
import subprocess

import pytest
import yaml

from mavtest import ROOT, require_binary
from mppi_mavlink import settings, vehicle

SHIPPED = ROOT / "config" / "vehicles" / "sim_rate_1kg.yaml"
GOOD = {"name": "v", "model": "quadrotor_rate", "mass": 1.4, "hover_thrust": 0.45,
        "limits": {"max_thrust": 25.0, "max_body_rate": [8, 8, 4]},
        "rate_response": {"tau": [0.06, 0.06, 0.1], "gain": 1.0, "delay": 0.01}}


def write(tmp_path, doc, name="v.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(doc))
    return p


def test_the_bridge_takes_the_thrust_map_from_the_vehicle_file(tmp_path):
    s = settings.load(ROOT / "config" / "bridge" / "px4_sitl.yaml")
    assert s["vehicle"]["name"] == "sim_rate_1kg" and s["vehicle"]["mass"] == 1.0
    assert s["vehicle"]["hover_thrust"] is None  # read from the autopilot
    s = settings.load(None, [f"vehicle.file={write(tmp_path, GOOD)}"])
    assert s["vehicle"]["mass"] == 1.4 and s["vehicle"]["hover_thrust"] == 0.45


def test_a_different_value_in_the_bridge_settings_is_refused_naming_both(tmp_path):
    v = write(tmp_path, GOOD)
    with pytest.raises(settings.SettingsError, match=r"vehicle\.mass: --set vehicle\.mass gives 1\.2 .*v\.yaml gives 1\.4"):
        settings.load(None, [f"vehicle.file={v}", "vehicle.mass=1.2"])
    conf = write(tmp_path, {"vehicle": {"file": str(v), "hover_thrust": 0.5}}, "bridge.yaml")
    with pytest.raises(settings.SettingsError, match=r"vehicle\.hover_thrust: .*bridge\.yaml gives 0\.5"):
        settings.load(conf)
    assert settings.load(None, [f"vehicle.file={v}", "vehicle.mass=1.4"])["vehicle"]["mass"] == 1.4  # the same: fine


def test_written_vehicle_files_read_back(tmp_path):
    v = vehicle.parse({**GOOD, "estimate_lag": 0.025})
    vehicle.dump(v, tmp_path / "out.yaml", header="written by a test")
    back = vehicle.load(tmp_path / "out.yaml")
    assert back["rate_response"] == v["rate_response"] and back["mass"] == 1.4
    assert back["estimate_lag"] == 0.025 and vehicle.parse(GOOD)["estimate_lag"] == 0.0
    assert (tmp_path / "out.yaml").read_text().startswith("# written by a test")


BAD = [
    ({**GOOD, "colour": "red"}, "colour: unknown field"),
    ({k: v for k, v in GOOD.items() if k != "mass"}, "mass"),
    ({**GOOD, "rate_response": {"tau": [0.05, 0.05]}}, "rate_response.tau"),
    ({**GOOD, "hover_thrust": 1.5}, "hover_thrust"),
    ({**GOOD, "model": "hexacopter"}, "model"),
    ({**GOOD, "params": {"mass": 2}}, "params.mass"),
    ({**GOOD, "estimate_lag": 0.8}, "estimate_lag"),
]


@pytest.mark.parametrize("doc,field", BAD, ids=[f for _, f in BAD])
def test_the_bridge_and_mppid_refuse_the_same_files(tmp_path, doc, field):
    p = write(tmp_path, doc)
    with pytest.raises(vehicle.VehicleError, match=field.split(":")[0].replace(".", r"\.")):
        vehicle.load(p)
    mppid = require_binary("mppid")
    r = subprocess.run([str(mppid), "--config", ROOT / "config/tasks/quadrotor_rate_track.yaml", "--vehicle", p,
                        "--lcm-url", "memq://", "--duration", "0.1"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and field.split(":")[0] in r.stderr + r.stdout, r.stderr


def test_mppid_flies_the_file_the_bridge_accepts(tmp_path):
    mppid = require_binary("mppid")
    p = write(tmp_path, GOOD)
    vehicle.load(p)
    r = subprocess.run([str(mppid), "--config", ROOT / "config/tasks/quadrotor_rate_track.yaml", "--vehicle", p,
                        "--lcm-url", "memq://", "--duration", "0.1"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
