"""The monitor's MAVLink side: one UDP socket (``udpin:HOST:PORT``), one parser per peer, counted rejects.

Why one parser per peer: pymavlink keeps partial bytes between calls, so two vehicles sharing a parser
would corrupt each other's frames. Why reset the parser after every datagram: the contract puts whole
frames in each datagram, so bytes left over are a truncated frame that would otherwise swallow the start
of the next, good, datagram. Why a guarded signature check: pymavlink stores a frame's signing timestamp
*before* it checks the hash, so one wrongly signed frame with a future timestamp would make every later
genuine frame look like a replay (see ecosystem.md); the guard undoes that store when the hash fails.

Nothing here knows the plant: a datagram becomes ``Telemetry`` (MAVLink units and ``time_usec``), and
the vehicle table turns that into a sample index with the vehicle's own ``h``.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass, fields
from typing import Callable

from monitor.errors import UserError
from monitor.wire.fastframe import ACTUATOR, AOA_SSA, ATTITUDE, Frame, split_telemetry
from monitor.wire.fastframe import encode_command as fast_encode_command
from monitor.wire.mavlink import (
    MONITOR_COMPONENT,
    Command,
    bump_signing_clock,
    enable_signing,
    encode_command,
    mavlink,
    new_codec,
)

__all__ = ["Telemetry", "LinkCounters", "MavlinkDecoder", "UdpEndpoint", "parse_udpin", "MONITOR_SYSID"]

log = logging.getLogger(__name__)

MONITOR_SYSID = 255  # a ground-station id, as MAVProxy uses; vehicles are 1-254
_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
_BAD_DATA = mavlink.MAVLINK_MSG_ID_BAD_DATA
_UNKNOWN = mavlink.MAVLINK_MSG_ID_UNKNOWN
_DEG_PER_RAD = 57.29577951308232


def parse_udpin(spec: str) -> tuple[str, int]:
    """``udpin:127.0.0.1:14550`` -> ``("127.0.0.1", 14550)``; anything else is a one-line UserError."""
    kind, _, rest = spec.partition(":")
    host, _, port = rest.rpartition(":")
    if kind != "udpin" or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"--mavlink '{spec}': expected udpin:HOST:PORT, e.g. udpin:127.0.0.1:14550")
    return host, int(port)


class Telemetry:
    """One vehicle sample as received: MAVLink units converted to plant units, instant still in us."""

    __slots__ = ("sysid", "time_usec", "alpha_deg", "q_deg_s", "elevator_deg")

    def __init__(self, sysid: int, time_usec: int, alpha_deg: float, q_deg_s: float) -> None:
        self.sysid = sysid
        self.time_usec = time_usec
        self.alpha_deg = alpha_deg
        self.q_deg_s = q_deg_s
        self.elevator_deg: float | None = None


@dataclass
class LinkCounters:
    """What arrived that was not a usable sample, by cause (the summary line and the tests read these)."""

    datagrams: int = 0
    samples: int = 0
    heartbeats: int = 0
    garbage: int = 0  # bad prefix, bad CRC, bad length: BAD_DATA other than signatures
    truncated: int = 0  # datagrams that ended inside a frame
    bad_signature: int = 0  # unsigned, wrong key or replayed (only with --signing-key)
    wrong_dialect: int = 0  # message ids unknown to ardupilotmega, and MAVLink 1 frames
    foreign: int = 0  # valid MAVLink 2 messages the monitor does not consume
    incomplete: int = 0  # AOA_SSA without the ATTITUDE of the same instant in its datagram
    peers_evicted: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class _Peer:
    __slots__ = ("codec", "last_seen")

    def __init__(self, codec: mavlink.MAVLink, now: float) -> None:
        self.codec = codec
        self.last_seen = now


def _guard_signature_check(codec: mavlink.MAVLink) -> None:
    """Make a failed signature check leave the stored stream timestamp as it was."""
    original = codec.check_signature
    streams = codec.signing.stream_timestamps
    missing = object()

    def checked(msgbuf, src_system: int, src_component: int) -> bool:
        stream = (msgbuf[-13], src_system, src_component)
        before = streams.get(stream, missing)
        if original(msgbuf, src_system, src_component):
            return True
        if before is missing:
            streams.pop(stream, None)
        else:
            streams[stream] = before
        return False

    codec.check_signature = checked


class MavlinkDecoder:
    """Datagrams in, ``Telemetry`` out, per peer address; also encodes the replies with that peer's codec."""

    def __init__(self, signing_key: bytes | None = None, max_peers: int = 4096, peer_timeout: float = 60.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.signing_key = signing_key
        self.max_peers = max_peers
        self.peer_timeout = peer_timeout
        self.clock = clock
        self.counters = LinkCounters()
        self._peers: dict[object, _Peer] = {}

    def _peer(self, addr: object, now: float) -> _Peer:
        peer = self._peers.get(addr)
        if peer is None:
            if len(self._peers) >= self.max_peers:
                self.evict(now, force=True)
            codec = new_codec(MONITOR_SYSID, MONITOR_COMPONENT)
            if self.signing_key is not None:
                enable_signing(codec, self.signing_key)
                _guard_signature_check(codec)
            peer = self._peers[addr] = _Peer(codec, now)
        peer.last_seen = now
        return peer

    def evict(self, now: float, force: bool = False) -> None:
        """Forget peers silent for ``peer_timeout`` s (with ``force``: at least the stalest one)."""
        stale = [a for a, p in self._peers.items() if now - p.last_seen > self.peer_timeout]
        if force and not stale and self._peers:
            stale = [min(self._peers, key=lambda a: self._peers[a].last_seen)]
        for addr in stale:
            del self._peers[addr]
        self.counters.peers_evicted += len(stale)

    def decode(self, data: bytes, addr: object) -> list[Telemetry]:
        """Every complete sample in one datagram (normally one). Never raises on bad input.

        Unsigned links try ``fastframe.split_telemetry`` first; any datagram it does not vouch for goes
        through pymavlink, which does the counting of rejects.
        """
        c = self.counters
        c.datagrams += 1
        codec = self._peer(addr, self.clock()).codec
        frames = split_telemetry(data) if self.signing_key is None else None
        if frames is None:
            frames = self._parse(codec, data)
        out = _assemble(frames, c)
        c.samples += len(out)
        return out

    def _parse(self, codec: mavlink.MAVLink, data: bytes) -> list[Frame]:
        """pymavlink's robust parse of a datagram: rejects counted, telemetry as ``Frame`` tuples."""
        c = self.counters
        try:
            msgs = codec.parse_buffer(data) or []
        except Exception as exc:  # robust parsing should prevent this; a packet must never stop the loop
            log.debug("parser raised on a datagram: %s", exc)
            msgs = []
            c.garbage += 1
        if len(codec.buf) > codec.buf_index:
            c.truncated += 1
            codec.buf = bytearray()
            codec.buf_index = 0
            codec.expected_length = mavlink.HEADER_LEN_V1 + 2
            codec.have_prefix_error = False
        frames: list[Frame] = []
        for msg in msgs:
            mid = msg._header.msgId  # the class attribute `id` is 0 for BAD_DATA
            if mid == _BAD_DATA:
                if msg.reason == "Invalid signature":
                    c.bad_signature += 1
                else:
                    c.garbage += 1
            elif mid == _UNKNOWN or msg._msgbuf[0] == 0xFE:
                c.wrong_dialect += 1
            elif mid == ATTITUDE:
                frames.append((mid, msg._header.srcSystem, msg.time_boot_ms, msg.pitchspeed))
            elif mid == AOA_SSA:
                frames.append((mid, msg._header.srcSystem, msg.time_usec, msg.AOA))
            elif mid == ACTUATOR:
                frames.append((mid, msg._header.srcSystem, msg.time_usec, msg.actuator[0]))
            elif mid == _HEARTBEAT:
                c.heartbeats += 1
            else:
                c.foreign += 1
        return frames

    def encode_command(self, addr: object, command: Command, h: float) -> bytes:
        """The reply frame, from the codec of the peer the sample came from (its own sequence and signing)."""
        peer = self._peers.get(addr)
        if peer is None:  # evicted between decode and reply: a fresh codec is still correct
            peer = self._peer(addr, self.clock())
        if self.signing_key is None:
            return fast_encode_command(peer.codec, command, h)
        return encode_command(peer.codec, command, h)

    def bump_signing_clocks(self) -> None:
        """Keep outgoing signing timestamps at wall-clock time (pymavlink only adds 1 per frame)."""
        if self.signing_key is not None:
            for peer in self._peers.values():
                bump_signing_clock(peer.codec)


def _assemble(frames: list[Frame], c: LinkCounters) -> list[Telemetry]:
    """Samples from one datagram's telemetry frames: AOA_SSA needs the ATTITUDE of its instant before it."""
    out: list[Telemetry] = []
    attitude: dict[int, tuple[int, float]] | None = None
    for mid, sysid, instant, value in frames:
        if mid == ATTITUDE:
            if attitude is None:
                attitude = {}
            attitude[sysid] = instant, value
        elif mid == AOA_SSA:
            att = attitude.get(sysid) if attitude is not None else None
            if att is None or att[0] != (instant // 1000) & 0xFFFFFFFF:
                c.incomplete += 1
                continue
            out.append(Telemetry(sysid, instant, value, att[1] * _DEG_PER_RAD))
        else:  # ACTUATOR
            for tel in out:
                if tel.sysid == sysid and tel.time_usec == instant:
                    tel.elevator_deg = value
    return out


class UdpEndpoint(asyncio.DatagramProtocol):
    """The asyncio socket: hands every datagram with its receive time to ``on_datagram`` and never raises."""

    def __init__(self, on_datagram: Callable[[bytes, object, int], None]) -> None:
        self.on_datagram = on_datagram
        self.transport: asyncio.DatagramTransport | None = None
        self.errors = 0

    def connection_made(self, transport) -> None:  # type: ignore[override]
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:  # type: ignore[override]
        t0 = time.perf_counter_ns()
        try:
            self.on_datagram(data, addr, t0)
        except Exception:  # a bug in handling one packet costs a log line, never the loop
            self.errors += 1
            log.exception("error handling a datagram from %s", addr)

    def error_received(self, exc: Exception) -> None:  # e.g. ICMP port unreachable after a vehicle quit
        log.debug("UDP error: %s", exc)

    def send(self, data: bytes, addr) -> None:
        if self.transport is not None:
            self.transport.sendto(data, addr)
