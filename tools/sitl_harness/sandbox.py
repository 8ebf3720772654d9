"""The processes of one run, kept apart and stopped cleanly whatever happens: a private
network namespace, spawning into it, stopping and the clean-up. Used by the flights
(flights/) and by the soak (tools/soak.py).

Isolation: `unshare -n` makes a namespace holding only a loopback interface, with the
multicast range routed to it, and a tiny `sleep` holding it open (start_namespace); every
process spawned then joins it with `nsenter -n`, so parallel runs each have their own LCM
bus and no datagram can leave the machine. Every such process is in one process group (the
holder's), so a single killpg reaches all of them: SIGTERM first, SIGKILL after a grace
period. Children also get PR_SET_PDEATHSIG, so even a SIGKILLed harness leaves no orphan.

A run whose own process must be on the private bus too (the soak relays and watches it)
re-executes itself inside a namespace instead (enter_private_network); its children then
need no nsenter, and a Sandbox without start_namespace() spawns them as they are.
"""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from . import paths

_NETNS_SETUP = "ip link set lo up && ip route add 224.0.0.0/4 dev lo && echo ready && exec sleep 86400"


class SandboxError(RuntimeError):
    pass


def deathsig_setter(sig: int = signal.SIGTERM):
    """A preexec_fn: the child gets `sig` when the thread that spawned it ends (the harness
    SIGKILLed included). Only safe when that thread lives as long as the child."""
    def set_deathsig():
        try:
            libc = ctypes.CDLL("libc.so.6", use_errno=True)
            libc.prctl(1, sig)  # PR_SET_PDEATHSIG
        except OSError:
            pass
    return set_deathsig


def fifo_allowed() -> bool:
    """Whether this process may start SCHED_FIFO children (root, or CAP_SYS_NICE), and is
    to: MPPID_NO_FIFO=1 keeps every process of the flight in the normal scheduler, for work
    beside a real-time measurement (a soak, a benchmark) that must not be preempted."""
    if os.environ.get("MPPID_NO_FIFO"):
        return False
    try:
        return subprocess.run(["chrt", "-f", "1", "true"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL).returncode == 0
    except OSError:
        return False


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # Zombies count as alive for killpg; reap check through /proc.
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                parts = f.read().rsplit(")", 1)[1].split()
            if int(parts[2]) == pgid and parts[0] != "Z":
                return True
        except (OSError, IndexError, ValueError):
            continue
    return False


def enter_private_network(flag: str = "MPPID_SOAK_NETNS") -> None:
    """Re-executes this script inside `unshare -n` (root, or a user namespace) with lo up and
    multicast routed to it, once (`flag` in the environment marks the second start)."""
    if os.environ.get(flag) == "1":
        subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
        subprocess.run(["ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)
        return
    os.environ[flag] = "1"
    pre = ["unshare", "-n"] if os.geteuid() == 0 else ["unshare", "-r", "-n"]
    os.execvp(pre[0], pre + ["--", sys.executable, os.path.abspath(sys.argv[0])] + sys.argv[1:])


class Sandbox:
    """Named processes, each logging to OUT/<name>.log. With start_namespace(): in their own
    network namespace and process group. deathsig: what a child gets when its spawning thread
    ends; any_thread: set it for spawns from other threads than the main one too (the caller
    keeps those threads alive as long as their children)."""

    def __init__(self, out: Path, deathsig: int = signal.SIGTERM, any_thread: bool = False):
        self.out = Path(out)
        self.deathsig = deathsig
        self.any_thread = any_thread
        self.procs: dict[str, subprocess.Popen] = {}
        self.holder: subprocess.Popen | None = None
        self.pgid: int | None = None
        self.logs: dict = {}

    def preexec(self):
        main = threading.current_thread() is threading.main_thread()
        return deathsig_setter(self.deathsig) if main or self.any_thread else None

    def start_namespace(self):
        if os.geteuid() != 0:
            # Unprivileged: a user namespace grants the capabilities to set up lo.
            cmd = ["unshare", "-r", "-n", "--", "sh", "-c", _NETNS_SETUP]
        else:
            cmd = ["unshare", "-n", "--", "sh", "-c", _NETNS_SETUP]
        self.holder = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, process_group=0,
                                       preexec_fn=self.preexec())
        line = self.holder.stdout.readline().decode().strip()
        if line != "ready":
            try:  # its shell exits right after the failing command: say what it said
                self.holder.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                pass
            err = self.holder.stderr.read().decode() if self.holder.poll() is not None else ""
            raise SandboxError(f"network namespace set-up failed: {line} {err}".strip())
        self.pgid = self.holder.pid

    def open_log(self, name: str):
        """OUT/<name>.log, kept open across restarts of the same name (they append)."""
        if name not in self.logs:
            self.logs[name] = open(self.out / f"{name}.log", "wb")
        return self.logs[name]

    def spawn(self, name: str, cmd: list) -> subprocess.Popen:
        """Starts `cmd` as `name` (inside the namespace, if started); stdout and stderr to its log."""
        ns = []
        if self.holder is not None:
            ns = ["nsenter", "-t", str(self.holder.pid), "-n"]
            if os.geteuid() != 0:
                ns = ["nsenter", "-t", str(self.holder.pid), "-U", "-n", "--preserve-credentials"]
            ns.append("--")
        p = subprocess.Popen(ns + [str(c) for c in cmd], stdout=self.open_log(name), stderr=subprocess.STDOUT,
                             stdin=subprocess.DEVNULL, process_group=self.pgid, cwd=paths.ROOT,
                             preexec_fn=self.preexec())
        self.procs[name] = p
        return p

    def returncode(self, name: str) -> int | None:
        """The exit code of `name`, None while it runs."""
        return self.procs[name].poll()

    def wait_ready(self, name: str, timeout: float):
        """Waits for `{"event": "ready"}` on a helper's log (it has subscribed), or fails."""
        deadline = time.monotonic() + timeout
        path = self.out / f"{name}.log"
        while '"event": "ready"' not in path.read_text(errors="replace"):
            if self.procs[name].poll() is not None:
                raise SandboxError(f"{name} exited at start (rc={self.procs[name].returncode}); see {name}.log")
            if time.monotonic() > deadline:
                raise SandboxError(f"{name} not subscribed after {timeout:g} s; see {name}.log")
            time.sleep(0.02)

    def terminate(self, name: str, grace: float):
        """SIGCONT (it may be stopped) and SIGTERM to `name`; SIGKILL after `grace` seconds."""
        p = self.procs.get(name)
        if p is None or p.poll() is not None:
            return
        try:
            p.send_signal(signal.SIGCONT)
            p.send_signal(signal.SIGTERM)
            p.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=5)
        except ProcessLookupError:
            pass

    def signal_group(self, sig, wait_s: float) -> bool:
        """sig to the process group, then up to wait_s for it to be gone; True if gone (or
        never started: the namespace's set-up failed before the group existed)."""
        if self.pgid is None:
            return True
        try:
            os.killpg(self.pgid, sig)
        except ProcessLookupError:
            pass
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and group_alive(self.pgid):
            time.sleep(0.05)
        return not group_alive(self.pgid)

    def stop(self, last: str | None = None, drain_s: float = 0.3):
        """Stops everything: every process but `last`, then `last` (a logger: after drain_s,
        so it has recorded the others' last messages), then the holder; then SIGKILL to
        whatever is left of the process group. Safe to call twice. Further SIGINT/SIGTERM are
        ignored meanwhile, so a second Ctrl-C cannot cut the clean-up short."""
        main = threading.current_thread() is threading.main_thread()
        saved = {}
        if main:
            for sig in (signal.SIGINT, signal.SIGTERM):
                saved[sig] = signal.signal(sig, signal.SIG_IGN)
        try:
            self._stop(last, drain_s)
        finally:
            for sig, h in saved.items():
                signal.signal(sig, h)

    def _stop(self, last, drain_s):
        for name in [n for n in self.procs if n != last]:
            self.terminate(name, 3.0)
        if last in self.procs and self.procs[last].poll() is None:
            time.sleep(drain_s)  # the logger drains what is still in its socket
        if last is not None:
            self.terminate(last, 3.0)
        if self.holder is not None:
            if not self.signal_group(signal.SIGTERM, 2.0):
                self.signal_group(signal.SIGKILL, 5.0)
            for p in list(self.procs.values()) + [self.holder]:
                try:
                    p.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    pass
        for f in self.logs.values():
            f.close()
        self.logs = {}

    def pids(self) -> dict:
        """{"pgid", "holder", name: pid} (pids.json)."""
        return {"pgid": self.pgid, "holder": self.holder.pid if self.holder else None,
                **{k: p.pid for k, p in self.procs.items()}}
