"""What the operator is told on the ground station: STATUSTEXT from the bridge (component
191) on the autopilot's link, which the autopilot routes to the ground station as it does any
companion's messages. One per engagement change and per refusal; a text longer than 50
characters goes as MAVLink 2 chunks (one id, chunk_seq 0, 1, ..., the last shorter than 50)."""
from __future__ import annotations

import itertools

from .autopilots.base import mavlink

INFO, NOTICE, WARNING, CRITICAL = (mavlink.MAV_SEVERITY_INFO, mavlink.MAV_SEVERITY_NOTICE,
                                   mavlink.MAV_SEVERITY_WARNING, mavlink.MAV_SEVERITY_CRITICAL)
MAX_CHUNKS = 6   # 299 characters: the longest refusal (GUID_OPTIONS) whole


def chunks(text: str) -> list[bytes]:
    """The text in 50-byte pieces; an empty last piece when the text fills the last exactly."""
    b = text.encode()[:50 * MAX_CHUNKS - 1]
    out = [b[i:i + 50] for i in range(0, len(b), 50)] or [b""]
    if len(out[-1]) == 50:
        out.append(b"")
    return out


class Notices:
    def __init__(self, link):
        self.link = link
        self.ids = itertools.cycle(range(1, 65536))
        self.sent = []   # (severity, text), the latest 64: status and tests

    def tell(self, severity: int, text: str) -> None:
        pieces = chunks(text)
        cid = next(self.ids) if len(pieces) > 1 else 0
        for i, piece in enumerate(pieces):
            self.link.send(lambda mv, p=piece, i=i: mv.statustext_send(severity, p, cid, i))
        self.sent = self.sent[-63:] + [(severity, text)]
