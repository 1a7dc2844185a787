"""The real-time shell around ``Simulation``: an asyncio UDP socket, a scaled clock, signals.

Clock: simulated time is ``(loop.time() - start) * speedup``, so delays, heartbeats and the monitor's own
computing time all scale together. Events are processed in time order by one driver task; a datagram
first brings the simulation up to its arrival time, then is handed over, so the integrator never goes
backwards.

Socket: the vehicle binds its own UDP socket (``--bind``, default an ephemeral loopback port), sends to
the ``udpout`` address and receives the commands on that same socket, as MAVProxy's ``udpout`` does.
"""

from __future__ import annotations

import asyncio
import logging
import signal
from dataclasses import dataclass

from monitor.wire.mavlink import (
    VEHICLE_COMPONENT,
    bump_signing_clock,
    enable_signing,
    encode_heartbeat,
    new_codec,
)
from monitor.wire.telemetry import Sample, encode_sample
from sim_vehicle.flight_model import FlightModelError
from sim_vehicle.link import CommandDecoder
from sim_vehicle.simulation import Simulation
from sim_vehicle.truth import TruthPublisher

__all__ = ["UdpSink", "VehicleProtocol", "run_daemon"]

log = logging.getLogger(__name__)


@dataclass
class UdpSink:
    """Encodes the simulation's outputs and sends them from the vehicle's socket."""

    transport: asyncio.DatagramTransport
    target: tuple[str, int]
    sysid: int
    h: float
    truth: TruthPublisher
    key: bytes | None = None
    decoder: CommandDecoder | None = None

    def __post_init__(self) -> None:
        self.mav = new_codec(self.sysid, VEHICLE_COMPONENT)
        if self.key is not None:
            enable_signing(self.mav, self.key)
        self.errors = 0

    def _send(self, data: bytes) -> None:
        try:
            self.transport.sendto(data, self.target)
        except OSError as exc:
            self.errors += 1
            log.debug("send failed: %s", exc)

    def send_sample(self, sample: Sample) -> None:
        self._send(encode_sample(self.mav, sample, self.h))

    def send_heartbeat(self) -> None:
        if self.key is not None:  # keep both signing clocks at wall-clock time (see the ecosystem notes)
            bump_signing_clock(self.mav)
            if self.decoder is not None:
                self.decoder.bump_clock()
        self._send(encode_heartbeat(self.mav, vehicle=True))

    def publish_truth(self, payload: dict) -> None:
        self.truth.publish(payload)


class VehicleProtocol(asyncio.DatagramProtocol):
    """Feeds datagrams to the decoder and the commands to the simulation, stamped in simulated time."""

    def __init__(self, daemon: _Daemon) -> None:
        self.daemon = daemon

    def datagram_received(self, data: bytes, addr) -> None:
        self.daemon.on_datagram(data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP "port unreachable" while the monitor is not up yet: expected, count it and go on
        self.daemon.icmp_errors += 1
        log.debug("socket error: %s", exc)


class _Daemon:
    def __init__(self, sim: Simulation, decoder: CommandDecoder, speedup: float) -> None:
        self.sim = sim
        self.decoder = decoder
        self.speedup = speedup
        self.loop = asyncio.get_running_loop()
        self.start = self.loop.time()
        self.wake = asyncio.Event()
        self.stop = asyncio.Event()
        self.icmp_errors = 0
        self.failure: FlightModelError | None = None  # the flight model could not go on (a crash): stop, report

    def now(self) -> float:
        return (self.loop.time() - self.start) * self.speedup

    def on_datagram(self, data: bytes, addr) -> None:
        try:
            commands = self.decoder.feed(data, addr)
            if not commands:
                return
            t = self.now()
            self.sim.run_until(t)
            for cmd in commands:
                outcome = self.sim.receive_command(cmd.k, cmd.elevator_deg, t)
                log.debug("command k=%d u=%r at t=%.4f: %s", cmd.k, cmd.elevator_deg, t, outcome)
            self.wake.set()
        except FlightModelError as exc:  # the aircraft crashed while the command was being brought up to time
            self.failure = exc
            self.request_stop()
        except Exception:  # one bad packet costs a log line, never the loop
            log.exception("error handling a datagram from %s", addr)

    def request_stop(self) -> None:
        self.stop.set()
        self.wake.set()

    async def drive(self) -> None:
        while not self.sim.done and not self.stop.is_set():
            self.sim.run_until(self.now())
            nxt = self.sim.next_time()
            if self.sim.done or nxt is None:
                break
            self.wake.clear()
            timeout = max(0.0, (nxt - self.now()) / self.speedup)
            try:
                await asyncio.wait_for(self.wake.wait(), timeout)
            except TimeoutError:
                pass
        if self.failure is not None:
            raise self.failure


async def run_daemon(
    sim: Simulation,
    decoder: CommandDecoder,
    truth: TruthPublisher,
    *,
    target: tuple[str, int],
    bind: tuple[str, int],
    speedup: float,
    key: bytes | None,
) -> None:
    """Run until the simulation finishes or SIGINT/SIGTERM; the socket is closed on the way out."""
    loop = asyncio.get_running_loop()
    daemon = _Daemon(sim, decoder, speedup)
    transport, _ = await loop.create_datagram_endpoint(lambda: VehicleProtocol(daemon), local_addr=bind)
    sink = UdpSink(transport, target, sim.sysid, sim.h, truth, key, decoder)
    sim.sink = sink
    daemon.start = loop.time()  # simulated time starts once the socket is up
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, daemon.request_stop)
    local = transport.get_extra_info("sockname")
    log.info("vehicle %d: sending to udp %s:%d from %s:%d, speedup %g", sim.sysid, *target, *local[:2], speedup)
    try:
        await daemon.drive()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        transport.close()
        sim.stats.packets.update(decoder.packets)
        sim.stats.commands.update(decoder.commands)
        sim.stats.packets["send_errors"] += sink.errors + daemon.icmp_errors
        if daemon.stop.is_set() and daemon.failure is None:
            log.info("stopped by signal at simulated t = %.3f s", daemon.now())
