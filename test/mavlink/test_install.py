"""The bridge and the mission tool install as packages (issue 28): `pip install ./lcmtypes
./drivers/mavlink ./drivers/mission` into a new venv gives working `mppid-mavlink-bridge` and
`mppid-mission` commands, with the LCM types generated from the .lcm files by the build,
without a build tree and without the repository on the path.

Offline and quick: the three folders are copied out of the checkout (the build writes beside
its sources) and built without isolation and without an index. The new venv finds what they
declare they need (lcm, pymavlink, pyyaml, numpy; pip resolves it) and the build tools
(setuptools, lcm-gen) in this venv's site-packages, after its own. The commands then fly: the
simulated PX4 -> the installed bridge -> LCM -> the installed mission tool holding a point, in
a private network namespace."""
import json
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from mavtest import LCM_URL, PYTHON, ROOT, wait_for

pytestmark = pytest.mark.timeout(180)

PACKAGES = ("lcmtypes", "drivers/mavlink", "drivers/mission")
CLEAN_ENV = {"PATH": "/usr/bin:/bin", "PYTHONUNBUFFERED": "1", "LC_ALL": "C.UTF-8"}


def _copy_sources(dst: Path) -> list[Path]:
    junk = shutil.ignore_patterns("build", "*.egg-info", "__pycache__", "*.pyc")
    out = []
    for rel in PACKAGES:
        shutil.copytree(ROOT / rel, dst / rel, ignore=junk)
        out.append(dst / rel)
    for generated in (dst / "lcmtypes").glob("*/*.py"):  # an editable install's, in the checkout
        generated.unlink()
    return out


def _new_venv(venv: Path) -> Path:
    """A venv of the base interpreter, this venv's site-packages after its own (plain paths:
    their .pth files, such as editable installs of this checkout, are not run)."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    own = Path(subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                              check=True, capture_output=True, text=True).stdout.strip())
    deps = [p for p in sys.path if p.endswith(("site-packages", "dist-packages")) and Path(p).is_dir()]
    (own / "_mppid_test_deps.pth").write_text("".join(f"{p}\n" for p in deps))
    return py


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("install")
    sources = _copy_sources(tmp / "src")
    py = _new_venv(tmp / "venv")
    r = subprocess.run([PYTHON, "-m", "pip", "--python", str(py), "install", "--disable-pip-version-check",
                        "--no-index", "--no-build-isolation", *map(str, sources)],
                       capture_output=True, text=True, timeout=120, cwd=tmp)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return tmp / "venv"


def test_packages_import_from_the_new_venv_alone(venv, tmp_path):
    code = ("import json, mppi_lcm, mppi_mavlink_lcm, mppi_mavlink, mppi_mission\n"
            "from mppi_mavlink import lcm_types\n"
            "t = lcm_types.import_mppi_lcm().vehicle_state_t(); t.n = 3; t.x = [1.0, 2.0, 3.0]\n"
            "l = lcm_types.import_link_type()(); l.dialect = 'px4'\n"
            "assert list(mppi_lcm.vehicle_state_t.decode(t.encode()).x) == [1.0, 2.0, 3.0]\n"
            "assert mppi_mavlink_lcm.mavlink_link_t.decode(l.encode()).dialect == 'px4'\n"
            "print(json.dumps({m.__name__: m.__file__ for m in (mppi_lcm, mppi_mavlink_lcm, mppi_mavlink, mppi_mission)}))")
    r = subprocess.run([venv / "bin" / "python", "-c", code], capture_output=True, text=True, env=CLEAN_ENV,
                       cwd=tmp_path, timeout=60)
    assert r.returncode == 0, r.stderr
    files = json.loads(r.stdout)
    site_dir = str(venv.resolve())
    assert all(f.startswith(site_dir) for f in files.values()), files  # none from the checkout or a build tree
    for cmd in ("mppid-mavlink-bridge", "mppid-mission"):
        assert (venv / "bin" / cmd).is_file(), cmd


class Listener:
    """What came on the LCM bus, decoded with this checkout's types (the installed ones wrote
    it): the mission's references, the bridge's link status. Read on a thread of its own so
    the socket never fills while the test waits."""

    def __init__(self):
        import lcm
        from mppi_mavlink import lcm_types
        self.ref_t, self.link_t = lcm_types.import_mppi_lcm().reference_t, lcm_types.import_link_type()
        self.references, self.link_up = 0, False
        self.bus = lcm.LCM(LCM_URL)
        self.bus.subscribe("MPPI_REFERENCE", self._on_reference)
        self.bus.subscribe("MPPI_MAVLINK_LINK", self._on_link)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        while not self.stop.is_set():
            self.bus.handle_timeout(50)

    def _on_reference(self, ch, data):
        self.ref_t.decode(data)
        self.references += 1

    def _on_link(self, ch, data):
        self.link_up = self.link_up or bool(self.link_t.decode(data).link_up)

    def close(self):
        self.stop.set()
        self.thread.join(5)


def test_installed_bridge_and_mission_fly_the_simulated_autopilot(venv, netns, procs, tmp_path):
    heard = Listener()
    try:
        _fly(venv, procs, tmp_path, heard)
    finally:
        heard.close()


def _fly(venv, procs, tmp_path, heard):
    procs.start("vehicle", [PYTHON, "-m", "mavlink_vehicle", "--url", "udpout:127.0.0.1:14540", "--out", tmp_path])
    sock = str(tmp_path / "bridge.sock")
    bridge = venv / "bin" / "mppid-mavlink-bridge"
    with open(tmp_path / "bridge.log", "wb") as log:
        procs.p["bridge"] = subprocess.Popen([bridge, "run", "--url", "udpin:127.0.0.1:14540", "--lcm-url", LCM_URL,
                                              "--set", f"control.socket={sock}"], stdout=log, stderr=subprocess.STDOUT,
                                             env=CLEAN_ENV, cwd=tmp_path)

    def status():
        r = subprocess.run([bridge, "status", "--socket", sock, "--timeout", "5"], capture_output=True, text=True,
                           env=CLEAN_ENV, cwd=tmp_path, timeout=30)
        return json.loads(r.stdout)["status"] if r.returncode == 0 else None

    st = wait_for(lambda: (s := status()) and s["link_up"] and s["states_published"] > 50 and s, 30,
                  "the installed bridge publishing the simulated PX4's states")
    assert st["dialect"] == "px4", st

    m = subprocess.run([venv / "bin" / "mppid-mission", "hold", "--for", "1", "--lcm-url", LCM_URL,
                        "--out", str(tmp_path / "mission"), "--quiet"],
                       capture_output=True, text=True, env=CLEAN_ENV, cwd=tmp_path, timeout=60)
    assert m.returncode == 0, m.stdout[-2000:] + m.stderr[-2000:]
    summary = json.loads((tmp_path / "mission" / "mission_summary.json").read_text())
    assert summary["outcome"] == "done", summary
    wait_for(lambda: heard.link_up and heard.references > 0, 10, "the mission's reference and the link status on LCM")

    procs.stop("bridge")
    assert procs.p["bridge"].returncode == 0, procs.log("bridge")[-2000:]
