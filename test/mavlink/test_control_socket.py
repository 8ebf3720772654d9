"""The bridge's control socket (mppi_mavlink/control.py) is its user's alone: created mode
0600 (never wider, not even between bind and chmod), owned by the bridge's user, and a
connection from another user is refused by the kernel. Whoever can connect can arm."""
import os
import socket
import stat
import subprocess
import sys

import pytest

from mppi_mavlink import control


@pytest.fixture
def server(tmp_path):
    s = control.ControlServer(str(tmp_path / "run" / "control.sock"), lambda line: {"ok": True, "message": line})
    s.start()
    yield s
    s.close()


def test_socket_is_owner_only(server):
    st = os.stat(server.path)
    assert stat.S_ISSOCK(st.st_mode)
    assert stat.S_IMODE(st.st_mode) == 0o600
    assert st.st_uid == os.geteuid()
    assert control.request(server.path, "status", 5.0) == {"ok": True, "message": "status"}


def test_socket_mode_does_not_follow_a_permissive_umask(tmp_path):
    old = os.umask(0)
    try:
        s = control.ControlServer(str(tmp_path / "c.sock"), lambda line: {"ok": True, "message": line})
        assert os.umask(0) == 0  # the server put the process umask back
    finally:
        os.umask(old)
    s.start()
    try:
        assert stat.S_IMODE(os.stat(s.path).st_mode) == 0o600
    finally:
        s.close()


def test_another_user_cannot_connect(server, tmp_path):
    """Not even one in the bridge's group (the socket used to be 0660)."""
    if os.geteuid() != 0:
        if os.environ.get("CI"):
            pytest.fail("CI runs as root: this check must run there")
        pytest.skip("needs root to act as another user (CI runs as root)")
    os.chmod(os.path.dirname(server.path), 0o755)  # the folder is not what refuses
    probe = (
        "import os, socket, sys\n"
        f"os.setgroups([]); os.setgid({os.getegid()}); os.setuid(65534)\n"
        "s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)\n"
        "try:\n"
        f"    s.connect({server.path!r})\n"
        "except PermissionError:\n"
        "    sys.exit(13)\n"
        "sys.exit(0)\n")
    r = subprocess.run([sys.executable, "-c", probe], timeout=10)
    assert r.returncode == 13, "another user connected to the control socket"
    # The owner still can.
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.connect(server.path)
