"""MAVLink 2 message signing on the bridge's link.

The key is the link's shared secret: 32 bytes, the same as on the autopilot (PX4: the key
set with SETUP_SIGNING, stored on its SD card; ArduPilot: `signing setup` in MAVProxy, or
SETUP_SIGNING). Anyone who holds it can command the vehicle, so the key file must be a
regular file owned by the bridge's user and readable or writable by nobody else (mode 0600
or 0400): a group- or world-accessible key is refused with an error naming the file and
its mode. The file holds the key as 64 hex digits (whitespace ignored) or as the 32 raw
bytes. Under systemd, `LoadCredential=` hands the service such a file
(`$CREDENTIALS_DIRECTORY/...`, which the path may name).

With a key, every message the bridge sends is signed, and of what it receives only
messages signed with the key and with a timestamp newer than the last one of their stream
(link id, system, component) are accepted. Unsigned ones (MAVLink 1 included), wrong
signatures and replays are dropped before the bridge sees them and counted
(`counters()`: rejected_unsigned, rejected_bad_signature).

pymavlink's own check records a stream's timestamp before it verifies the signature, so a
single forged message carrying a timestamp far ahead would lock the real stream out until
that time; `_check_signature` verifies the signature first.
"""
from __future__ import annotations

import hashlib
import hmac
import os
import stat
import time
import types
from pathlib import Path

KEY_BYTES = 32
# pymavlink's and the MAVLink specification's signing timestamp: 10 us units since 2015-01-01.
EPOCH_2015 = 1420070400


class SigningError(ValueError):
    pass


def load_key(path: str | Path) -> bytes:
    """The 32-byte key from `path` (environment variables and ~ expanded), after checking
    the file is private to this user. Raises SigningError saying what is wrong."""
    p = os.path.expanduser(os.path.expandvars(str(path)))
    try:
        fd = os.open(p, os.O_RDONLY)
    except OSError as e:
        raise SigningError(f"signing key {p}: cannot open: {e.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise SigningError(f"signing key {p}: not a regular file")
        if st.st_uid != os.geteuid():
            raise SigningError(f"signing key {p}: owned by uid {st.st_uid}, but the bridge runs as uid "
                               f"{os.geteuid()}; the key must belong to the bridge's user")
        mode = stat.S_IMODE(st.st_mode)
        if mode & 0o077:
            raise SigningError(f"signing key {p}: mode {mode:04o} lets group or others at it; a signing key must be "
                               f"readable only by its user (chmod 600 {p})")
        data = os.read(fd, 4096)
    finally:
        os.close(fd)
    if len(data) == KEY_BYTES:
        return bytes(data)
    text = b"".join(data.split())
    try:
        key = bytes.fromhex(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != KEY_BYTES:
        raise SigningError(f"signing key {p}: expected {KEY_BYTES} bytes, as 64 hex digits or raw")
    return key


def signing_timestamp_now() -> int:
    return int((max(time.time(), EPOCH_2015) - EPOCH_2015) * 100_000)


def _refuse_unsigned(_mav, _msg_id) -> bool:
    return False


def _check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
    """pymavlink's MAVLink.check_signature, with the signature verified before the stream's
    timestamp is recorded (see the module's docstring)."""
    s = self.signing
    digest = hashlib.sha256(s.secret_key + bytes(msgbuf[:-6])).digest()[:6]
    if not hmac.compare_digest(digest, bytes(msgbuf[-6:])):
        return False
    link_id = msgbuf[-13]
    tlow, thigh = self.mav_sign_unpacker.unpack(bytes(msgbuf[-12:-6]))
    timestamp = tlow + (thigh << 32)
    stream = (link_id, src_system, src_component)
    last = s.stream_timestamps.get(stream)
    if last is not None:
        if timestamp <= last:
            return False  # a replay, or out of order
    elif timestamp + 6000 * 1000 < s.timestamp:
        return False  # a new stream more than a minute behind our clock: a replay
    s.stream_timestamps[stream] = timestamp
    s.timestamp = max(s.timestamp, timestamp)
    return True


def install(mav, key: bytes, link_id: int) -> None:
    """Signs everything `mav` (a pymavlink MAVLink object, e.g. connection.mav) sends and
    accepts only correctly signed messages."""
    if len(key) != KEY_BYTES:
        raise SigningError(f"signing key must be {KEY_BYTES} bytes")
    s = mav.signing
    s.secret_key = bytes(key)
    s.sign_outgoing = True
    s.allow_unsigned_callback = _refuse_unsigned
    s.link_id = int(link_id)
    s.timestamp = signing_timestamp_now()
    mav.check_signature = types.MethodType(_check_signature, mav)


def counters(mav) -> dict:
    """Messages dropped by the signature check since `install`."""
    s = mav.signing
    # pymavlink counts a bad signature in both badsig_count and reject_count.
    return {"rejected_unsigned": int(s.reject_count - s.badsig_count), "rejected_bad_signature": int(s.badsig_count)}
