"""MAVLink 2 signing on the bridge's link (mppi_mavlink/signing.py): the key file must be
private; a signed link flies; an unsigned injector's SET_ATTITUDE_TARGET and COMMAND_LONG
(to the autopilot) and HEARTBEAT and ODOMETRY (to the bridge) are dropped and counted on
both sides; a wrong key never brings the link up; a forged signature cannot lock the real
stream out. The simulated autopilot checks signatures with pymavlink's own code, the
bridge with signing.py, so each side checks the other's implementation."""
import json
import os
import socket
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from linktools import UdpTap  # noqa: E402
from mavchain import Chain  # noqa: E402
from mavtest import PYTHON, ROOT, wait_for  # noqa: E402
from mppi_mavlink import signing  # noqa: E402

mavlink = mavutil.mavlink
KEY = bytes(range(1, 33))
TAP_PORT = 14562


def key_file(tmp_path, key=KEY, mode=0o600, name="signing.key"):
    p = tmp_path / name
    p.write_text(key.hex() + "\n")
    os.chmod(p, mode)
    return p


# ---- the key file -------------------------------------------------------------------------

def test_key_file_must_be_private(tmp_path):
    assert signing.load_key(key_file(tmp_path)) == KEY
    raw = tmp_path / "raw.key"
    raw.write_bytes(KEY)
    os.chmod(raw, 0o400)
    assert signing.load_key(raw) == KEY
    for mode in (0o640, 0o604, 0o644, 0o660, 0o620):
        p = key_file(tmp_path, mode=mode, name=f"k{mode:o}")
        with pytest.raises(signing.SigningError, match=rf"mode 0{mode:o} lets group or others at it.*chmod 600"):
            signing.load_key(p)
    short = key_file(tmp_path, key=KEY[:16], name="short.key")
    with pytest.raises(signing.SigningError, match="expected 32 bytes"):
        signing.load_key(short)
    with pytest.raises(signing.SigningError, match="cannot open"):
        signing.load_key(tmp_path / "missing.key")
    if os.geteuid() == 0:
        other = key_file(tmp_path, name="other.key")
        os.chown(other, 65534, 65534)
        with pytest.raises(signing.SigningError, match="owned by uid 65534"):
            signing.load_key(other)


def test_bridge_refuses_a_readable_key_at_start(tmp_path):
    """The bridge exits 2 naming the file and its mode, before opening anything."""
    import subprocess
    k = key_file(tmp_path, mode=0o644)
    r = subprocess.run([PYTHON, "-m", "mppi_mavlink", "run", "--set", f"mavlink.signing_key_file={k}",
                        "--set", f"control.socket={tmp_path / 'c.sock'}", "--lcm-url", "memq://"],
                       cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT / "drivers" / "mavlink")},
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2, r.stderr
    assert f"signing key {k}: mode 0644" in r.stderr and "chmod 600" in r.stderr
    assert not (tmp_path / "c.sock").exists()


# ---- the signature check --------------------------------------------------------------------

def _endpoint(key, src=(1, 1), link_id=0):
    m = mavlink.MAVLink(None, srcSystem=src[0], srcComponent=src[1])
    m.robust_parsing = True
    if key is not None:
        signing.install(m, key, link_id)
    return m


def _heartbeat(sender):
    return sender.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0).pack(sender)


def _types(receiver, data):
    return [m.get_type() for m in receiver.parse_buffer(data) or []]


def test_only_messages_signed_with_the_key_are_taken():
    rx = _endpoint(KEY)
    good = _heartbeat(_endpoint(KEY))
    assert _types(rx, good) == ["HEARTBEAT"]
    assert _types(rx, good) == ["BAD_DATA"]                          # the same bytes again: a replay
    assert _types(rx, _heartbeat(_endpoint(None))) == ["BAD_DATA"]    # unsigned
    assert _types(rx, _heartbeat(_endpoint(bytes(32)))) == ["BAD_DATA"]  # another key
    v1 = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    assert _types(rx, v1.heartbeat_encode(2, 12, 0, 0, 0).pack(v1, force_mavlink1=True)) == ["BAD_DATA"]
    assert signing.counters(rx) == {"rejected_unsigned": 2, "rejected_bad_signature": 2}


def test_a_forged_signature_cannot_lock_the_stream_out():
    """A message with a wrong signature and a timestamp a day ahead, in the real sender's
    stream: dropped, and the real sender's next message is still taken (pymavlink's own
    check would have recorded the forged timestamp first and refused it)."""
    tx = _endpoint(KEY, src=(1, 1), link_id=3)
    forger = _endpoint(bytes(32), src=(1, 1), link_id=3)
    forger.signing.timestamp = tx.signing.timestamp + 100_000 * 86_400
    rx = _endpoint(KEY)
    assert _types(rx, _heartbeat(tx)) == ["HEARTBEAT"]
    assert _types(rx, _heartbeat(forger)) == ["BAD_DATA"]
    assert _types(rx, _heartbeat(tx)) == ["HEARTBEAT"]
    assert signing.counters(rx)["rejected_bad_signature"] == 1


# ---- a signed link in flight ------------------------------------------------------------

class Injector:
    """Unsigned MAVLink from the outside, impersonating the bridge's (1, 191) towards the
    autopilot and the autopilot's (1, 1) towards the bridge."""

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.as_bridge = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
        self.as_autopilot = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.sent_vehicle = self.sent_bridge = 0

    def to_vehicle(self, addr):
        m = self.as_bridge
        for msg in (m.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 3.0, -3.0, 3.0, 0.0),   # motors off
                    m.command_long_encode(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0),
                    m.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 4, 6, 0, 0, 0, 0)):  # AUTO.LAND
            self.sock.sendto(msg.pack(m), addr)
            self.sent_vehicle += 1

    def to_bridge(self, port):
        m = self.as_autopilot
        for msg in (m.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 1, 1 << 16, 3),
                    m.odometry_encode(0, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, 50.0, 50.0, -30.0,
                                      [1, 0, 0, 0], 0, 0, 0, 0, 0, 0, [float("nan")] + [0.0] * 20,
                                      [float("nan")] + [0.0] * 20)):
            self.sock.sendto(msg.pack(m), ("127.0.0.1", port))
            self.sent_bridge += 1


@pytest.mark.timeout(120)
def test_signed_link_flies_and_an_unsigned_injector_is_ignored(netns, procs, tmp_path):
    key = key_file(tmp_path)
    tap = UdpTap(TAP_PORT, 14540)
    try:
        c = Chain(procs, tmp_path, world="circle", task="quadrotor_rate_track",
                  bridge_sets=[f"mavlink.signing_key_file={key}"], vehicle_args=["--signing-key-file", key])
        c.listen_lcm()
        c.start_mppid()
        c.start_bridge()
        c.start_vehicle(url=f"udpout:127.0.0.1:{TAP_PORT}")
        wait_for(lambda: c.status().get("link_up") and not c.status().get("refusal"), 20, "the signed link up")
        wait_for(lambda: c.status().get("states_published", 0) >= 60 and c.status().get("streaming"), 15, "stream")
        assert c.status()["signing"] is True
        c.ok("offboard")
        c.ok("arm")
        c.wait_event("mission_start", 20)

        inj = Injector()
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            inj.to_vehicle(tap.vehicle)
            inj.to_bridge(14540)
            time.sleep(0.02)
        time.sleep(0.3)
        st = c.status()
        print(f"injected {inj.sent_vehicle} to the autopilot, {inj.sent_bridge} to the bridge; bridge {st}")
        assert st["rejected_unsigned"] >= 0.9 * inj.sent_bridge
        assert st["rejected_bad_signature"] == 0
        assert st["armed"] is True and st["mode"] == "OFFBOARD"       # the spoofed HEARTBEAT said MANUAL, disarmed
        assert st["streaming"] and st["link_up"]
        link = c.link_msgs[-1][1]
        assert link.signing == 1 and link.rejected_unsigned >= 0.9 * inj.sent_bridge

        c.wait_event("mission_done", 20)
        s = c.land_and_finish()                                         # a signed COMMAND_LONG, taken
        cnt = s["counters"]
        print(f"autopilot counters {cnt}; mission {s['mission']}")
        assert s["signing"] is True
        assert cnt["rejected_unsigned"] >= 0.9 * inj.sent_vehicle
        assert cnt["rejected_bad_signature"] == 0 and cnt["accepted_signed"] > 500
        # None of the injected messages reached the autopilot's logic: its record of what it
        # took has no motors-off setpoint and no disarm; it stayed OFFBOARD and armed until the
        # bridge's own (signed) land.
        wire = c.wire()
        assert not [r for r in wire if r["type"] == "SET_ATTITUDE_TARGET" and r["rates"] == [3.0, -3.0, 3.0]]
        taken = [(r["command"], r["params"][0]) for r in wire if r["type"] == "COMMAND_LONG"]
        assert (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0) not in taken       # the injected (force) disarm
        assert (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) in taken            # the bridge's own arm
        assert [e["mode"] for e in s["events"] if e["event"] == "mode"] == ["OFFBOARD", "AUTO.LAND"]
        assert not [e for e in s["events"] if e["event"] in ("collision", "failsafe")]
        assert s["mission"]["tracking_rmse"] < 0.3
        assert not s["armed"]
    finally:
        tap.close()


@pytest.mark.timeout(60)
def test_a_wrong_key_never_brings_the_link_up(netns, procs, tmp_path):
    c = Chain(procs, tmp_path, mppid=False, bridge_sets=[f"mavlink.signing_key_file={key_file(tmp_path)}"],
              vehicle_args=["--signing-key-file", key_file(tmp_path, key=bytes(32), name="other.key")])
    c.listen_lcm()
    c.start_bridge()
    c.start_vehicle()
    wait_for(lambda: c.status().get("rejected_bad_signature", 0) >= 10, 10, "the autopilot's messages refused")
    time.sleep(1.5)
    st = c.status()
    assert not st["link_up"] and st["states_published"] == 0 and st["target_system"] == 0
    s = c.stop_vehicle()
    assert s["counters"]["rejected_bad_signature"] >= 1      # the bridge's HEARTBEATs, refused there too
    assert s["companion"] is None
    print(json.dumps(st))
