"""The vehicle's MAVLink receive side: datagrams in, elevator commands out, everything else counted.

Why one parser reset after every datagram (not one parser per peer): every sender on this link puts whole
frames in each datagram, so leftover bytes mean a truncated datagram, and a reset stops them from
corrupting the next one. One parser also means one signing state, so a replayed command cannot slip in
from a new source port as a "new stream".

Signing guard: pymavlink stores a frame's timestamp for its stream *before* checking the signature, so a
forged frame with a future timestamp would make every later genuine frame look replayed. The stream
timestamps are restored after any rejected frame, keeping only those of frames that verified.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

from monitor.wire.mavlink import (
    VEHICLE_COMPONENT,
    bump_signing_clock,
    command_elevator_deg,
    enable_signing,
    mavlink,
    new_codec,
    sample_index,
)
from monitor.wire.signing_key import load_signing_key  # shared with the monitor: one key-file format

__all__ = ["ReceivedCommand", "CommandDecoder", "load_signing_key"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReceivedCommand:
    k: int
    elevator_deg: float
    source: tuple


class CommandDecoder:
    """Decode datagrams for vehicle ``sysid``; counts land in ``packets`` and ``commands``."""

    def __init__(self, sysid: int, h: float, key: bytes | None = None) -> None:
        self.sysid = sysid
        self.h = h
        self.mav = new_codec(sysid, VEHICLE_COMPONENT)
        self.signed = key is not None
        if key is not None:
            enable_signing(self.mav, key, sign_outgoing=False)
        self.packets: Counter = Counter()
        self.commands: Counter = Counter()

    def feed(self, data: bytes, source: tuple) -> list[ReceivedCommand]:
        """All commands for this vehicle in one datagram (possibly none)."""
        snapshot = dict(self.mav.signing.stream_timestamps) if self.signed else None
        try:
            messages = self.mav.parse_buffer(data) or []
        except Exception as exc:  # robust parsing should not raise; never let a packet kill the loop
            log.debug("parser raised on a datagram from %s: %s", source, exc)
            messages = []
            self.packets["garbage"] += 1
        if self.mav.buf_len() > 0:
            self.packets["truncated"] += 1
            self._reset()
        out: list[ReceivedCommand] = []
        garbage = rejected = False
        for msg in messages:
            kind = msg.get_type()
            if kind == "BAD_DATA":
                if "signature" in str(getattr(msg, "reason", "")).lower():
                    rejected = True
                    self.packets["rejected_signature"] += 1
                else:
                    garbage = True
                continue
            if kind != "SET_ACTUATOR_CONTROL_TARGET":
                self.packets["other"] += 1
                continue
            if msg.target_system not in (self.sysid, 0):
                self.commands["foreign_target"] += 1
                continue
            out.append(ReceivedCommand(sample_index(msg.time_usec, self.h), command_elevator_deg(msg), source))
        if garbage:
            self.packets["garbage"] += 1
        if rejected and snapshot is not None:
            self._restore(snapshot, messages)
        return out

    def _reset(self) -> None:
        self.mav.buf = bytearray()
        self.mav.buf_index = 0
        self.mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        self.mav.have_prefix_error = False

    def _restore(self, snapshot: dict, messages: list) -> None:
        """Undo timestamps stored by frames that then failed their signature check."""
        for msg in messages:
            if getattr(msg, "_signed", False):
                buf = msg.get_msgbuf()
                stamp = int.from_bytes(buf[-12:-6], "little")
                stream = (msg._link_id, msg.get_srcSystem(), msg.get_srcComponent())
                snapshot[stream] = max(snapshot.get(stream, 0), stamp)
        self.mav.signing.stream_timestamps.clear()
        self.mav.signing.stream_timestamps.update(snapshot)

    def bump_clock(self) -> None:
        if self.signed:
            bump_signing_clock(self.mav)
