"""Where bytes come from and go to: ``--mavlink`` connections as MAVProxy/mavutil users write them.

* ``udpin:HOST:PORT`` listen for datagrams; every source address is a peer (vehicles, routers).
* ``udpout:HOST:PORT`` send to a router or vehicle that listens; the 1 Hz HEARTBEAT is what makes a
  router (MAVProxy ``--out=udpin:``, mavlink-router) learn our address and route vehicles back.
* ``tcp:HOST:PORT`` connect (an autopilot SITL on 5760, a router's TCP server); reconnect with back-off.
* ``tcpin:HOST:PORT`` listen for TCP connections; every connection is a peer.

Each link turns bytes into frames with its own ``FrameParser`` (one per TCP connection, since a stream
keeps partial frames; one per UDP link, since a datagram never does) and hands ``(route, frames, t0)`` to
the pipeline, where ``route = (link, peer)`` is where the answer goes. Nothing here knows the plant.

Why the UDP peer table is an LRU ``OrderedDict``: it is touched on every datagram, so it must be O(1)
(a flood from many source ports must not cost the real vehicle its samples), and bounded.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import socket
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

from monitor.errors import UserError
from monitor.link.frames import FrameCounters, FrameEncoder, FrameParser, RawFrame
from monitor.link.outgoing import MONITOR_COMPONENT, MONITOR_SYSID, heartbeat_frame
from monitor.link.signing import Signer

__all__ = ["ConnectionSpec", "parse_connection", "Link", "open_link", "FrameHandler"]

log = logging.getLogger(__name__)

KINDS = ("udpin", "udpout", "tcp", "tcpin")
_ALIASES = {"udp": "udpin"}  # mavutil's spelling
FrameHandler = Callable[[tuple, list[RawFrame], int], None]


@dataclass(frozen=True)
class ConnectionSpec:
    kind: str
    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.kind}:{host}:{self.port}"


def parse_connection(text: str, allow_remote: bool = True) -> ConnectionSpec:
    """``udpin:127.0.0.1:14550`` -> ConnectionSpec; anything else is a one-line UserError."""
    kind, _, rest = text.partition(":")
    kind = _ALIASES.get(kind, kind)
    host, _, port = rest.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if kind not in KINDS or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"--mavlink '{text}': expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or "
                        "tcpin:HOST:PORT (e.g. udpin:127.0.0.1:14550)")
    if kind in ("udpout", "tcp") and int(port) == 0:
        raise UserError(f"--mavlink '{text}': {kind} needs the peer's port, not 0")
    return ConnectionSpec(kind, host, int(port))


def resolve(spec: ConnectionSpec) -> tuple[str, int]:
    """The address to bind or reach; an unresolvable host is a one-line UserError."""
    try:
        infos = socket.getaddrinfo(spec.host, spec.port, type=socket.SOCK_DGRAM if spec.kind.startswith("udp")
                                   else socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise UserError(f"--mavlink {spec}: cannot resolve host '{spec.host}' ({exc.strerror or exc})") from None
    addr = infos[0][4]
    return addr[0], addr[1]


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.split("%")[0]).is_loopback
    except ValueError:
        return False


class Link:
    """One connection: a parser per byte stream, an encoder for what we send, heartbeats for its peers."""

    def __init__(self, spec: ConnectionSpec, index: int, handler: FrameHandler, counters: FrameCounters,
                 signer: Signer | None) -> None:
        self.spec = spec
        self.index = index
        self.handler = handler
        self.counters = counters
        self.signer = signer
        self.encoder = FrameEncoder(MONITOR_SYSID, MONITOR_COMPONENT, signer)
        self.send_errors = 0
        self.local: str = str(spec)

    def new_parser(self, stream: bool) -> FrameParser:
        return FrameParser(self.counters, self.signer, stream=stream)

    def send(self, data: bytes, peer: object) -> None:
        raise NotImplementedError

    def peers(self) -> list[object]:
        raise NotImplementedError

    def heartbeat(self) -> None:
        for peer in self.peers():
            self.send(heartbeat_frame(self.encoder), peer)

    async def start(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __repr__(self) -> str:
        return str(self.spec)


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, link: "UdpLink") -> None:
        self.link = link

    def datagram_received(self, data: bytes, addr) -> None:  # type: ignore[override]
        self.link.on_datagram(data, addr, time.perf_counter_ns())

    def error_received(self, exc: Exception) -> None:  # e.g. ICMP port unreachable after a vehicle quit
        log.debug("%s: %s", self.link.spec, exc)


class UdpLink(Link):
    """``udpin`` (bind, answer every sender) and ``udpout`` (send to one address, answer it)."""

    def __init__(self, *args, max_peers: int = 1024, peer_timeout: float = 30.0, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.parser = self.new_parser(stream=False)
        self.transport: asyncio.DatagramTransport | None = None
        self.max_peers = max_peers
        self.peer_timeout = peer_timeout
        self._peers: OrderedDict[object, float] = OrderedDict()
        self.peers_evicted = 0
        self.remote: tuple | None = None

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        host, port = resolve(self.spec)
        try:
            if self.spec.kind == "udpin":
                self.transport, _ = await loop.create_datagram_endpoint(lambda: _Datagrams(self), local_addr=(host, port))
            else:
                self.remote = (host, port)
                self.transport, _ = await loop.create_datagram_endpoint(lambda: _Datagrams(self), remote_addr=(host, port))
                self._peers[self.transport.get_extra_info("peername")] = time.monotonic()
        except OSError as exc:
            raise UserError(f"--mavlink {self.spec}: {exc.strerror or exc}"
                            + (" (is another monitor or MAVProxy using this port?)" if exc.errno == 98 else "")) from None
        sock = self.transport.get_extra_info("sockname")
        self.local = f"{self.spec.kind}:{sock[0]}:{sock[1]}" if self.spec.kind == "udpin" else str(self.spec)

    def on_datagram(self, data: bytes, addr, t0: int) -> None:
        peers = self._peers
        if addr in peers:
            peers.move_to_end(addr)
        elif len(peers) >= self.max_peers:
            peers.popitem(last=False)
            self.peers_evicted += 1
        peers[addr] = time.monotonic()
        frames = self.parser.feed(data)
        if frames:
            self.handler((self, addr), frames, t0)

    def peers(self) -> list[object]:
        if self.spec.kind == "udpout":
            return list(self._peers)[:1]
        horizon = time.monotonic() - self.peer_timeout
        return [a for a, seen in self._peers.items() if seen >= horizon]

    def send(self, data: bytes, peer: object) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        try:
            if self.remote is not None:
                self.transport.sendto(data)
            else:
                self.transport.sendto(data, peer)
        except OSError as exc:
            self.send_errors += 1
            log.debug("%s: send failed: %s", self.spec, exc)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


class _Connection(asyncio.Protocol):
    """One TCP connection: its own stream parser (partial frames survive across reads)."""

    def __init__(self, link: "TcpLink") -> None:
        self.link = link
        self.parser = link.new_parser(stream=True)
        self.transport: asyncio.Transport | None = None
        self.closed = asyncio.get_running_loop().create_future()
        self.peer = "?"

    def connection_made(self, transport) -> None:  # type: ignore[override]
        self.transport = transport
        self.peer = "%s:%s" % tuple(transport.get_extra_info("peername")[:2])
        self.link.connections.add(self)
        log.info("%s: connected to %s", self.link.spec, self.peer)

    def data_received(self, data: bytes) -> None:
        t0 = time.perf_counter_ns()
        frames = self.parser.feed(data)
        if frames:
            self.link.handler((self.link, self), frames, t0)

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
            self.local = f"tcpin:{sock[0]}:{sock[1]}"
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


def open_link(spec: ConnectionSpec, index: int, handler: FrameHandler, counters: FrameCounters,
              signer: Signer | None) -> Link:
    cls = UdpLink if spec.kind.startswith("udp") else TcpLink
    return cls(spec, index, handler, counters, signer)
