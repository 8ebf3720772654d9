"""Flights that take turns on one machine.

With $MPPID_REALTIME_LOCK naming a file, a flight (real time or lock-step: its simulator,
daemon and recorder run SCHED_FIFO, and a lock-step flight keeps every core busy until it
ends) holds an exclusive lock on it (flock) while it flies: flights started on this machine
with the same file fly one after another. The Python tests set it (test/conftest.py), and the
MAVLink tests' chains hold it too: beside another worker's flight, a real-time mppid lost a
third of a second of commands, a chain's stand-in controller stopped answering for 200 ms, a
flight's recorder lost states from its log. A campaign's pinned flights (--realtime-jobs N)
have cores of their own and do not take turns."""
from __future__ import annotations

import fcntl
import os

ENV = "MPPID_REALTIME_LOCK"


class RealtimeTurn:
    """Held from acquire() to release() (or as a context manager); nothing without $MPPID_REALTIME_LOCK."""

    def __init__(self):
        self._file = None

    @property
    def held(self) -> bool:
        return self._file is not None

    def acquire(self) -> RealtimeTurn:
        path = os.environ.get(ENV)
        if path and self._file is None:
            f = open(path, "a")  # noqa: SIM115 - held until release()
            fcntl.flock(f, fcntl.LOCK_EX)
            self._file = f
        return self

    def release(self) -> None:
        if self._file is not None:
            fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()
            self._file = None

    def __enter__(self) -> RealtimeTurn:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
