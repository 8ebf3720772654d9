"""Third-party MAVLink peers on the link, none of them written here:

* MAVProxy (PyPI `MAVProxy`) routes between the simulated autopilot and the rest;
* MAVSDK (PyPI `mavsdk` 4.x: the C++ library in the wheel, driven through ctypes; no
  mavsdk_server, no network) is a ground station on the link that also forwards between its
  two connections, so it sees both the autopilot and the bridge:

    vehicle <-> MAVProxy (udpin 14550, out udpout 14541) <-> MAVSDK (udpin 14541 <-> udpout
    14540, forwarding) <-> bridge (udpin 14540) <-> LCM <-> mppid

A short flight (offboard, arm, mppid takes off and holds, land) goes through both. A peer
that cannot be imported or run is a skip that says exactly why.
"""
import math
import time

import os

import pytest

from mavtest import wait_for
from mavchain import ROUTER_IN, Chain
from mppi_mavlink import frames

pytestmark = pytest.mark.timeout(120)



def _missing(why: str):
    """Both peers come from requirements.txt: in CI (CI set) their absence is a failure."""
    if os.environ.get("CI"):
        pytest.fail(why)
    pytest.skip(why)

def _mavsdk():
    try:
        import mavsdk
        from mavsdk import ComponentType, Configuration, Mavsdk
        return mavsdk, ComponentType, Configuration, Mavsdk
    except Exception as e:  # the wheel ships a native library: a load failure is a skip
        _missing(f"MAVSDK (PyPI mavsdk) not usable here: {e!r}; pip install mavsdk")


def _mavproxy():
    try:
        import MAVProxy  # noqa: F401
    except Exception as e:
        _missing(f"MAVProxy (PyPI MAVProxy) not installed: {e!r}; pip install MAVProxy")


def test_mavproxy_router_and_mavsdk_ground_station(netns, procs, tmp_path):
    _mavproxy()
    mavsdk, ComponentType, Configuration, Mavsdk = _mavsdk()
    c = Chain(procs, tmp_path, world="circle", router=True)
    c.listen_lcm()
    c.start_router(extra_outs=())
    # MAVProxy's single out goes to MAVSDK, not to the bridge.
    procs.stop("mavproxy")
    cmd = procs.p.pop("mavproxy").args
    cmd = [a.replace("udpout:127.0.0.1:14540", "udpout:127.0.0.1:14541") for a in cmd]
    procs.start("mavproxy", cmd)
    gcs = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        r1 = gcs.add_any_connection_with_forwarding("udpin://127.0.0.1:14541", mavsdk.ForwardingOption.ON)
        r2 = gcs.add_any_connection_with_forwarding("udpout://127.0.0.1:14540", mavsdk.ForwardingOption.ON)
        assert r1 == mavsdk.ConnectionResult.SUCCESS and r2 == mavsdk.ConnectionResult.SUCCESS, (r1, r2)
        c.start_bridge()
        c.start_mppid()
        c.start_vehicle(url=f"udpout:127.0.0.1:{ROUTER_IN}")
        system = gcs.first_autopilot(15.0)
        assert system is not None, f"MAVSDK found no autopilot; mavproxy log:\n{procs.log('mavproxy')[-2000:]}"
        wait_for(lambda: c.status().get("link_up") and not c.status().get("refusal"), 20, "bridge link up")
        wait_for(lambda: c.status().get("states_published", 0) >= 60, 10, "1.2 s of state")

        # MAVSDK understands the simulated autopilot ...
        assert system.is_connected()
        assert system.autopilot_type().name == "PX4", system.autopilot_type()
        assert system.vehicle_type().name in ("QUADROTOR", "MULTICOPTER"), system.vehicle_type()
        # ... and sees the bridge's companion heartbeat (component 191) on the same system.
        wait_for(lambda: 191 in system.component_ids(), 5, "component 191 (the bridge) in MAVSDK's system")
        tele = system.telemetry() if callable(getattr(system, "telemetry", None)) else None
        if tele is None:
            from mavsdk.plugins.telemetry import Telemetry
            tele = Telemetry(system)

        c.ok("offboard")
        c.ok("arm")
        c.wait_event("mission_start", 20)
        assert tele.armed()
        assert tele.flight_mode().name == "OFFBOARD", tele.flight_mode()
        # MAVSDK's position and attitude against the truth, through our conversion.
        pv = tele.position_velocity_ned()
        q = tele.attitude_quaternion()
        truth = [r for r in c.out.joinpath("truth.jsonl").read_text().splitlines() if '"x"' in r][-1]
        import json
        x = json.loads(truth)["x"]
        p_enu = frames.ned_to_enu((pv.position.north_m, pv.position.east_m, pv.position.down_m))
        print(f"MAVSDK position NED ({pv.position.north_m:.2f}, {pv.position.east_m:.2f}, {pv.position.down_m:.2f}) "
              f"-> ENU {tuple(round(v, 2) for v in p_enu)}; truth {tuple(round(v, 2) for v in x[0:3])}")
        assert math.dist(p_enu, x[0:3]) < 0.5            # 50 Hz telemetry, a moving vehicle
        assert p_enu[2] > 1.0
        q_enu = frames.q_ned_frd_to_enu_flu((q.w, q.x, q.y, q.z))
        assert abs(sum(a * b for a, b in zip(q_enu, x[6:10]))) > 0.95   # same attitude, within a few degrees
        c.ok("land")
        c.wait_event("landed", 20)
        wait_for(lambda: not tele.armed(), 5, "MAVSDK to see the vehicle disarmed")
        c.stop_vehicle()
        assert c.status()["setpoints_sent"] > 100
    finally:
        gcs.destroy()
