"""mppid's systemd protocol without systemd: a unix datagram socket as NOTIFY_SOCKET and
WATCHDOG_USEC set, as systemd does for Type=notify with WatchdogSec. Checks READY=1 (after
the self-test and warm-up logs), WATCHDOG=1 pings at WatchdogSec/4, a STATUS= line with rate
and misses, STOPPING=1 and exit 0 on SIGTERM. Usage: notify_test.py MPPID CONFIG"""
import argparse
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time


def main():
    parser = argparse.ArgumentParser(description=__doc__.split(". ")[0])
    parser.add_argument("mppid", help="the mppid binary")
    parser.add_argument("config", help="the daemon configuration it runs")
    args = parser.parse_args()
    mppid, config = args.mppid, args.config
    d = tempfile.mkdtemp()
    path = os.path.join(d, "notify")
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.settimeout(0.05)
    env = dict(os.environ, NOTIFY_SOCKET=path, WATCHDOG_USEC="400000")
    err_path = os.path.join(d, "err")
    with open(err_path, "w") as err:
        p = subprocess.Popen([mppid, "--config", config, "--lcm-url", "memq://"], env=env, stderr=err,
                             stdout=subprocess.DEVNULL)
    got = []  # (time, line)
    t0 = time.monotonic()
    term_at = None
    while time.monotonic() - t0 < 30:
        try:
            msg = s.recv(4096).decode()
            for line in msg.split("\n"):
                got.append((time.monotonic(), line))
        except socket.timeout:
            pass
        ready = [t for t, l in got if l == "READY=1"]
        if ready and term_at is None and time.monotonic() - ready[0] > 1.2:
            term_at = time.monotonic()
            p.send_signal(signal.SIGTERM)
        if p.poll() is not None:
            break
    rc = p.wait(timeout=5)
    log = open(err_path).read()
    lines = [l for _, l in got]
    ready_t = next((t for t, l in got if l == "READY=1"), None)
    pings = [t for t, l in got if l == "WATCHDOG=1" and ready_t and t > ready_t and (term_at is None or t < term_at)]
    status = [l for l in lines if l.startswith("STATUS=")]
    checks = [
        (ready_t is not None, "READY=1 sent"),
        ("transport self-test passed" in log and "ready:" in log, "READY after self-test and warm-up (log)"),
        (len(pings) >= 6, "WATCHDOG=1 at ~100 ms while healthy (%d pings in ~1.2 s)" % len(pings)),
        (not any(l == "WATCHDOG=1" for t, l in got if ready_t and t < ready_t), "no WATCHDOG before READY"),
        (any("Hz" in l and "misses" in l for l in status), "STATUS= with rate and misses: %s" % (status[:1],)),
        ("STOPPING=1" in lines, "STOPPING=1 on SIGTERM"),
        (rc == 0, "exit code 0 (%s)" % rc),
    ]
    bad = [w for ok, w in checks if not ok]
    for ok, w in checks:
        print(("ok   " if ok else "FAIL ") + w)
    if bad:
        print(log)
        sys.exit(1)
    print("PASS")


if __name__ == "__main__":
    main()
