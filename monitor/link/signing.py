"""MAVLink 2 message signing, checked and applied here rather than inside pymavlink's parser.

Why our own: the specification keeps replay protection per *stream* (link id, system id, component id)
for the whole receiver, not per source address, so a frame replayed from a new UDP port must still be
refused; pymavlink's state lives in one codec per peer. pymavlink also stores a frame's timestamp
*before* checking its hash, so one forged frame with a future timestamp would make every later genuine
frame look replayed. Here the hash is checked first and only a verified frame moves its stream forward.

Timestamps are in units of 10 us since 2015-01-01 (the specification's epoch).
"""

from __future__ import annotations

import hashlib
import struct
import time

__all__ = ["SIGNATURE_LEN", "Signer", "now_timestamp"]

SIGNATURE_LEN = 13  # link id (1) + timestamp (6) + signature (6)
_EPOCH_2015 = 1420070400
_NEW_STREAM_WINDOW = 6_000_000  # a new stream may start at most 60 s behind our clock (the spec's rule)
_TS = struct.Struct("<Q")


def now_timestamp() -> int:
    """The signing clock: wall-clock time in 10 us units since 2015-01-01."""
    return int((time.time() - _EPOCH_2015) * 100_000)


class Signer:
    """One secret key: verifies incoming signed frames and signs outgoing ones.

    ``streams`` maps (link id, system id, component id) to the last accepted timestamp. It is shared by
    every link and peer of the monitor, which is what makes a replay from a new source port a replay.
    """

    def __init__(self, key: bytes, link_id: int = 0) -> None:
        if len(key) != 32:
            raise ValueError(f"MAVLink signing key must be 32 bytes, got {len(key)}")
        self.key = key
        self.link_id = link_id
        self.timestamp = now_timestamp()
        self.streams: dict[tuple[int, int, int], int] = {}
        self.max_streams = 4096

    def verify(self, frame: bytes | memoryview, sysid: int, compid: int) -> bool:
        """True if ``frame`` (a whole signed MAVLink 2 frame) carries a valid, fresh signature."""
        sig_at = len(frame) - 6
        if hashlib.sha256(self.key + bytes(frame[:sig_at])).digest()[:6] != bytes(frame[sig_at:]):
            return False
        link_id = frame[sig_at - 7]
        stamp = int.from_bytes(frame[sig_at - 6 : sig_at], "little")
        stream = (link_id, sysid, compid)
        last = self.streams.get(stream)
        if last is not None:
            if stamp <= last:
                return False
        elif stamp + _NEW_STREAM_WINDOW < max(self.timestamp, now_timestamp()):
            return False
        elif len(self.streams) >= self.max_streams:  # bounded: forget the oldest stream (dicts keep order)
            del self.streams[next(iter(self.streams))]
        self.streams[stream] = stamp
        if stamp > self.timestamp:
            self.timestamp = stamp
        return True

    def sign(self, frame: bytes) -> bytes:
        """The 13 signature bytes for an outgoing frame whose header already has the signed flag set."""
        self.timestamp = max(self.timestamp + 1, now_timestamp())
        tail = bytes((self.link_id,)) + _TS.pack(self.timestamp)[:6]
        return tail + hashlib.sha256(self.key + frame + tail).digest()[:6]
