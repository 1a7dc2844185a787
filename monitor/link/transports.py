"""Where bytes come from and go to: ``--mavlink`` connections as MAVProxy/mavutil users write them.

* ``udpin:HOST:PORT`` listen for datagrams; every source address is a peer (vehicles, routers).
* ``udpout:HOST:PORT`` send to a router or vehicle that listens; the 1 Hz HEARTBEAT is what makes a
  router (MAVProxy ``--out=udpin:``, mavlink-router) learn our address and route vehicles back.
* ``tcp:HOST:PORT`` connect (an autopilot SITL on 5760, a router's TCP server); reconnect with back-off.
* ``tcpin:HOST:PORT`` listen for TCP connections; every connection is a peer.

Each link turns bytes into frames with its own ``FrameParser`` (one per TCP connection, since a stream
keeps partial frames; one per UDP link, since a datagram never does) and hands the pipeline a list of reads
``(route, frames, t0)``, where ``route = (link, peer)`` is where the answer goes and ``t0`` (``perf_counter_ns``)
when the bytes arrived. Nothing here knows the plant.

Why a list: a UDP link drains everything its socket holds per wake-up of the event loop (bounded) and hands it
over in one call, so that the pipeline sees every vehicle's newest sample at once and can answer that one
instead of the queue behind it (``monitor.service.pipeline``, "Current, not queued"). ``t0`` is the kernel's
receive time (``SO_TIMESTAMPNS``) where the platform has it, so the time a datagram waited in the socket's
buffer counts in its age; elsewhere it is the time it was read.

Which MAVLink version a peer gets: the one it speaks. A peer whose last read held MAVLink 1 frames (a telemetry
radio, older firmware, ArduPilot's ``SERIALn_PROTOCOL = 1``) is answered with MAVLink 1 frames from the link's
v1 encoder (``encoder_for``), as ArduPilot itself answers; any MAVLink 2 frame from it switches it back. A
signed link only ever hears (and writes) signed MAVLink 2.

Why the UDP peer table is an LRU ``OrderedDict``: it is touched on every datagram, so it must be O(1)
(a flood from many source ports must not cost the real vehicle its samples), and bounded.
"""

from __future__ import annotations

import asyncio
import errno
import ipaddress
import logging
import socket
import struct
import sys
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

from monitor.errors import UserError
from monitor.link.frames import FrameCounters, FrameEncoder, FrameParser, RawFrame
from monitor.link.outgoing import MONITOR_COMPONENT, MONITOR_SYSID, heartbeat_frame
from monitor.link.signing import Signer

__all__ = ["ConnectionSpec", "parse_connection", "Link", "open_link", "FrameHandler", "Read"]

log = logging.getLogger(__name__)

KINDS = ("udpin", "udpout", "tcp", "tcpin")
_ALIASES = {"udp": "udpin"}  # mavutil's spelling
Read = tuple[tuple, list[RawFrame], int]  # (route, frames, t0 in perf_counter_ns)
FrameHandler = Callable[[list[Read]], None]
# SO_TIMESTAMPNS (Linux: 35, which Python's socket module does not name): each datagram's kernel receive time
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform.startswith("linux") else None)
_TIMESPEC = struct.Struct("@qq")  # struct timespec on a 64-bit Linux: tv_sec, tv_nsec


@dataclass(frozen=True)
class ConnectionSpec:
    kind: str
    host: str
    port: int

    def __str__(self) -> str:
        return format_connection(self.kind, self.host, self.port)


def format_connection(kind: str, host: str, port: int) -> str:
    """``udpin:127.0.0.1:14550``, ``udpin:[::1]:14550``: how MAVProxy users write a connection."""
    return f"{kind}:[{host}]:{port}" if ":" in host else f"{kind}:{host}:{port}"


def parse_connection(text: str, allow_remote: bool = True) -> ConnectionSpec:
    """``udpin:127.0.0.1:14550`` -> ConnectionSpec; anything else is a one-line UserError."""
    kind, _, rest = text.partition(":")
    kind = _ALIASES.get(kind, kind)
    host, _, port = rest.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if kind not in KINDS or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(
            f"--mavlink '{text}': expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or "
            "tcpin:HOST:PORT (e.g. udpin:127.0.0.1:14550)"
        )
    if kind in ("udpout", "tcp") and int(port) == 0:
        raise UserError(f"--mavlink '{text}': {kind} needs the peer's port, not 0")
    return ConnectionSpec(kind, host, int(port))


def resolve(spec: ConnectionSpec) -> tuple[str, int]:
    """The address to bind or reach; an unresolvable host is a one-line UserError."""
    try:
        infos = socket.getaddrinfo(
            spec.host, spec.port, type=socket.SOCK_DGRAM if spec.kind.startswith("udp") else socket.SOCK_STREAM
        )
    except socket.gaierror as exc:
        raise UserError(f"--mavlink {spec}: cannot resolve host '{spec.host}' ({exc.strerror or exc})") from None
    except UnicodeError as exc:  # a label IDNA cannot encode (empty, over 63 characters): no strerror
        raise UserError(f"--mavlink {spec}: cannot resolve host '{spec.host}' ({exc})") from None
    addr = infos[0][4]
    return str(addr[0]), int(addr[1])  # an AF_INET/AF_INET6 address: (host, port, ...)


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.split("%")[0]).is_loopback
    except ValueError:
        return False


_errors_logged: set[str] = set()


def _guarded(handler: FrameHandler, reads: list[Read]) -> None:
    """A bug in handling reads costs a log line (the first of its kind with its traceback), never the loop."""
    try:
        handler(reads)
    except Exception as exc:
        kind = type(exc).__name__
        where = reads[0][0][1] if len(reads) == 1 else f"{len(reads)} reads"
        if kind not in _errors_logged:
            _errors_logged.add(kind)
            log.exception("error handling frames from %s (further %s errors logged at DEBUG)", where, kind)
        else:
            log.debug("error handling frames from %s: %s", where, exc)


class Link:
    """One connection: a parser per byte stream, an encoder for what we send, heartbeats for its peers."""

    datagram = False  # datagram links get the per-datagram caps (monitor/service/pipeline.py)

    def __init__(
        self, spec: ConnectionSpec, index: int, handler: FrameHandler, counters: FrameCounters, signer: Signer | None
    ) -> None:
        self.spec = spec
        self.index = index
        self.handler = handler
        self.counters = counters
        self.signer = signer
        self.encoder = FrameEncoder(MONITOR_SYSID, MONITOR_COMPONENT, signer)
        self._encoder_v1: FrameEncoder | None = None  # made when a MAVLink 1 peer is first answered
        self.send_errors = 0
        self.local: str = str(spec)

    def new_parser(self, stream: bool) -> FrameParser:
        return FrameParser(self.counters, self.signer, stream=stream)

    def speaks_v1(self, peer: object) -> bool:
        """Whether ``peer`` last spoke MAVLink 1 (it is then answered in MAVLink 1)."""
        return False

    def encoder_for(self, peer: object) -> FrameEncoder:
        """The encoder whose frames ``peer`` reads: MAVLink 1 for a v1 peer on an unsigned link, else the link's."""
        if self.signer is None and self.speaks_v1(peer):
            if self._encoder_v1 is None:
                self._encoder_v1 = FrameEncoder(MONITOR_SYSID, MONITOR_COMPONENT, version=1)
            return self._encoder_v1
        return self.encoder

    def send(self, data: bytes, peer: object) -> None:
        raise NotImplementedError

    def peers(self) -> list[object]:
        raise NotImplementedError

    def heartbeat(self) -> None:
        for peer in self.peers():
            self.send(heartbeat_frame(self.encoder_for(peer)), peer)

    async def start(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __repr__(self) -> str:
        return str(self.spec)


class UdpLink(Link):
    """``udpin`` (bind, answer every sender) and ``udpout`` (send to one address, answer it).

    Why a raw non-blocking socket with ``loop.add_reader`` instead of an asyncio datagram transport: the
    transport reads one datagram per pass of the event loop, so a burst of one-message-per-datagram
    traffic (a router forwarding ten vehicles) pays a full loop pass per message. The reader drains the socket
    until it is empty, up to ``burst`` datagrams per wake-up (bounded, so timers and other links still run, and so
    that a burst's first vehicles are answered before its last are read: 1,024 at once added ~1 ms to the round
    trip's p50 at 200 vehicles), and hands them to the pipeline in one call.
    """

    burst = 128
    datagram = True

    def __init__(self, *args, max_peers: int = 1024, peer_timeout: float = 30.0, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.parser = self.new_parser(stream=False)
        self.sock: socket.socket | None = None
        self.max_peers = max_peers
        self.peer_timeout = peer_timeout
        self._peers: OrderedDict[object, float] = OrderedDict()
        self.peers_evicted = 0
        self._v1_peers: set[object] = set()  # peers whose last datagram held MAVLink 1 frames
        self.remote: tuple | None = None
        self.stamped = False  # whether the kernel stamps each datagram's arrival (SO_TIMESTAMPNS)
        # datagrams older than this when read are not parsed but handed to ``on_stale`` (0: off): what arrived
        # while the monitor could not run is past every vehicle's deadline, and parsing it would only delay the rest
        self.stale_ns = 0
        self.on_stale: Callable[[list[bytes]], None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        host, port = resolve(self.spec)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
            if self.spec.kind == "udpin":
                sock.bind((host, port))
            else:
                sock.connect((host, port))
                self.remote = (host, port)
                self._peers[sock.getpeername()] = time.monotonic()
        except OSError as exc:
            sock.close()
            hint = " (is another monitor or MAVProxy using this port?)" if exc.errno == errno.EADDRINUSE else ""
            raise UserError(f"--mavlink {self.spec}: {exc.strerror or exc}{hint}") from None
        sock.setblocking(False)
        if _SO_TIMESTAMPNS is not None:
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self.stamped = True
            except OSError:  # not this platform's option: the read time stands in for the arrival
                pass
        self.sock = sock
        name = sock.getsockname()
        self.local = format_connection("udpin", name[0], name[1]) if self.spec.kind == "udpin" else str(self.spec)
        self._loop.add_reader(sock.fileno(), self._readable)

    def _readable(self) -> None:
        """Drain the socket (up to ``burst`` datagrams) and hand every read to the pipeline at once."""
        sock = self.sock
        if sock is None:
            return
        reads: list[Read] = []
        stale: list[bytes] = []
        clock = time.perf_counter_ns
        stamped = self.stamped
        # the kernel stamps with the wall clock: this offset turns a stamp into perf_counter_ns
        offset = clock() - time.time_ns() if stamped else 0
        horizon = clock() - self.stale_ns if stamped and self.stale_ns and self.on_stale is not None else 0
        seen = time.monotonic()  # when each peer was last heard, for the whole drain
        for _ in range(self.burst):
            try:
                if stamped:
                    data, ancillary, _flags, addr = sock.recvmsg(65535, 64)
                    if ancillary and len(ancillary[0][2]) >= _TIMESPEC.size:  # the one SCM_TIMESTAMPNS, inline
                        sec, nsec = _TIMESPEC.unpack_from(ancillary[0][2])
                        t0 = sec * 1_000_000_000 + nsec + offset
                    else:
                        t0 = _arrival(ancillary, offset) if ancillary else clock()
                else:
                    data, addr = sock.recvfrom(65535)
                    t0 = clock()
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # e.g. ICMP port unreachable reported on a connected socket
                log.debug("%s: %s", self.spec, exc)
                break
            if t0 < horizon:
                stale.append(data)
                continue
            read = self._read(data, addr, t0, seen)
            if read is not None:
                reads.append(read)
        if stale and self.on_stale is not None:
            self.on_stale(stale)
        if reads:
            _guarded(self.handler, reads)

    def on_datagram(self, data: bytes, addr, t0: int) -> None:
        """One datagram, handled at once (the drain hands many over in one call)."""
        read = self._read(data, addr, t0)
        if read is not None:
            _guarded(self.handler, [read])

    def _read(self, data: bytes, addr, t0: int, seen: float | None = None) -> Read | None:
        frames = self.parser.feed(data)
        if not frames:  # junk costs no bookkeeping, and its source gets no heartbeat (no reflection)
            return None
        peers = self._peers
        if addr in peers:
            peers.move_to_end(addr)
        elif len(peers) >= self.max_peers:
            self._v1_peers.discard(peers.popitem(last=False)[0])
            self.peers_evicted += 1
        peers[addr] = time.monotonic() if seen is None else seen
        if self.parser.version == 1:
            self._v1_peers.add(addr)
        elif self._v1_peers:
            self._v1_peers.discard(addr)
        return (self, addr), frames, t0

    def speaks_v1(self, peer: object) -> bool:
        return peer in self._v1_peers

    def peers(self) -> list[object]:
        if self.spec.kind == "udpout":
            return list(self._peers)[:1]
        horizon = time.monotonic() - self.peer_timeout
        return [a for a, seen in self._peers.items() if seen >= horizon]

    def send(self, data: bytes, peer: object) -> None:
        sock = self.sock
        if sock is None:
            return
        try:
            if self.remote is not None:
                sock.send(data)
            else:
                # a datagram link's peers are the addresses recvfrom returned
                sock.sendto(data, cast("tuple[Any, ...]", peer))
        except OSError as exc:  # a full buffer or an unreachable peer costs this frame only
            self.send_errors += 1
            log.debug("%s: send failed: %s", self.spec, exc)

    def close(self) -> None:
        if self.sock is not None:
            if self._loop is not None:
                self._loop.remove_reader(self.sock.fileno())
            self.sock.close()
            self.sock = None


class _Connection(asyncio.Protocol):
    """One TCP connection: its own stream parser (partial frames survive across reads).

    A stream's backlog after a stall is processed in order, but at most ``per_pass`` frames per pass of
    the event loop: the rest waits in ``_backlog`` for the next pass, so one connection's burst cannot keep
    the other links and the timers waiting.
    """

    per_pass = 256

    def __init__(self, link: TcpLink) -> None:
        self.link = link
        self.parser = link.new_parser(stream=True)
        self._backlog: list[RawFrame] = []
        self.transport: asyncio.Transport | None = None
        self.closed = asyncio.get_running_loop().create_future()
        self.peer = "?"

    def connection_made(self, transport) -> None:
        self.transport = transport
        host, port = transport.get_extra_info("peername")[:2]
        self.peer = f"{host}:{port}"
        self.link.connections.add(self)
        log.info("%s: connected to %s", self.link.spec, self.peer)

    def data_received(self, data: bytes) -> None:
        t0 = time.perf_counter_ns()
        frames = self.parser.feed(data)
        if not frames:
            return
        if self._backlog:  # keep the order: new frames queue behind the ones still waiting
            self._backlog.extend(frames)
            return
        self._process(frames, t0)

    def _process(self, frames: list[RawFrame], t0: int) -> None:
        now_frames, rest = frames[: self.per_pass], frames[self.per_pass :]
        _guarded(self.link.handler, [((self.link, self), now_frames, t0)])
        if rest:
            self._backlog = rest
            asyncio.get_running_loop().call_soon(self._drain)

    def _drain(self) -> None:
        frames, self._backlog = self._backlog, []
        if frames and self.transport is not None and not self.transport.is_closing():
            self._process(frames, time.perf_counter_ns())

    def is_closed(self) -> bool:
        return self.closed.done()

    def connection_lost(self, exc) -> None:
        self.link.connections.discard(self)
        log.info("%s: connection from %s closed%s", self.link.spec, self.peer, f" ({exc})" if exc else "")
        if not self.closed.done():
            self.closed.set_result(None)

    def __repr__(self) -> str:
        return f"tcp peer {self.peer}"


class TcpLink(Link):
    """``tcp`` (connect and keep reconnecting, back-off 0.5 s doubling to 5 s) and ``tcpin`` (serve)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.connections: set[_Connection] = set()
        self.server: asyncio.AbstractServer | None = None
        self._task: asyncio.Task | None = None
        self.reconnects = 0

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        host, port = resolve(self.spec)
        if self.spec.kind == "tcpin":
            try:
                self.server = await loop.create_server(lambda: _Connection(self), host, port)
            except OSError as exc:
                raise UserError(f"--mavlink {self.spec}: {exc.strerror or exc}") from None
            sock = self.server.sockets[0].getsockname()
            self.local = format_connection("tcpin", sock[0], sock[1])
        else:
            self._task = loop.create_task(self._keep_connected(host, port))

    async def _keep_connected(self, host: str, port: int) -> None:
        loop = asyncio.get_running_loop()
        backoff = 0.5
        while True:
            try:
                _, conn = await loop.create_connection(lambda: _Connection(self), host, port)
            except OSError as exc:
                log.warning("%s: cannot connect (%s); retrying in %.1f s", self.spec, exc.strerror or exc, backoff)
                await asyncio.sleep(backoff)
                backoff = min(backoff * 2, 5.0)
                continue
            backoff = 0.5
            await conn.closed
            self.reconnects += 1
            await asyncio.sleep(0.2)

    def speaks_v1(self, peer: object) -> bool:
        parser = getattr(peer, "parser", None)
        return parser is not None and parser.version == 1

    def peers(self) -> list[object]:
        return list(self.connections)

    def send(self, data: bytes, peer: object) -> None:
        transport = getattr(peer, "transport", None)
        if transport is not None and not transport.is_closing():
            transport.write(data)

    def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
        if self.server is not None:
            self.server.close()
        for conn in list(self.connections):
            if conn.transport is not None:
                conn.transport.close()


def _arrival(ancillary: list[tuple[int, int, bytes]], offset: int) -> int:
    """The kernel's receive stamp (``SCM_TIMESTAMPNS``, wall clock) as ``perf_counter_ns``."""
    for _level, _kind, payload in ancillary:
        if len(payload) >= _TIMESPEC.size:
            sec, nsec = _TIMESPEC.unpack_from(payload)
            return sec * 1_000_000_000 + nsec + offset
    return time.perf_counter_ns()


def open_link(
    spec: ConnectionSpec, index: int, handler: FrameHandler, counters: FrameCounters, signer: Signer | None
) -> Link:
    cls = UdpLink if spec.kind.startswith("udp") else TcpLink
    return cls(spec, index, handler, counters, signer)
