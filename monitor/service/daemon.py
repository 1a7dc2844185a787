"""The monitor daemon: wires the UDP endpoint, the vehicle table, Zenoh and the recorder around one loop.

The hot path (``Monitor.on_datagram``) is synchronous inside asyncio's datagram callback: parse, step
the estimator, answer with the command, hand the estimate to the Zenoh thread, hand the record to the
recorder. Nothing on it waits for I/O other than the non-blocking ``sendto``. Processing time is
measured per datagram from the moment the socket callback starts to the end of the hand-offs.

Shutdown (SIGINT/SIGTERM): stop reading, log the summary, drain the Zenoh queue (bounded), close the
recorder (which flushes and writes the footer), undeclare everything and close the session (bounded),
exit 0. A second signal during shutdown is ignored rather than leaving a half-written recording.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import signal
import socket
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

from monitor.service.alarm import AlarmConfig
from monitor.service.records import SampleRecord, TruthRecord
from monitor.service.udp_endpoint import MavlinkDecoder, UdpEndpoint
from monitor.service.vehicles import Fleet, VehicleTable
from monitor.wire.mavlink import Command

__all__ = ["MonitorConfig", "Monitor", "run_daemon", "default_name", "percentile"]

log = logging.getLogger("monitor.run")


def default_name() -> str:
    """``<host>-<pid>``: unique per process, readable in the liveliness key."""
    host = "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in socket.gethostname()) or "host"
    return f"{host}-{os.getpid()}"


def percentile(values, p: float) -> float | None:
    data = sorted(values)
    if not data:
        return None
    return data[min(len(data) - 1, int(round(p / 100 * (len(data) - 1))))]


@dataclass
class MonitorConfig:
    fleet: Fleet
    host: str = "127.0.0.1"
    port: int = 14550
    prefix: str = "uav"
    name: str = field(default_factory=default_name)
    rrd: str | None = None
    rrd_properties: dict[str, Any] = field(default_factory=dict)
    signing_key: bytes | None = None
    alarm: AlarmConfig = field(default_factory=AlarmConfig)
    vehicle_timeout: float = 10.0
    truth: bool = True
    queue_max: int = 10_000


class Monitor:
    """The loop's state and its hot path; sockets, Zenoh and the recorder are injected (tests, benchmark)."""

    def __init__(self, config: MonitorConfig, send: Callable[[bytes, object], None], publisher=None,
                 recorder=None) -> None:
        self.config = config
        self.decoder = MavlinkDecoder(config.signing_key)
        self.table = VehicleTable(config.fleet, config.alarm, config.vehicle_timeout)
        self.send = send
        self.publisher = publisher
        self.recorder = recorder
        self.processing_s: deque[float] = deque(maxlen=100_000)
        self.commands_sent = 0

    def on_datagram(self, data: bytes, addr: object, t0_ns: int) -> None:
        now = time.monotonic()
        wall = time.time()
        for tel in self.decoder.decode(data, addr):
            p = self.table.accept(tel, addr, now, wall)
            if p is None:
                continue
            v, r = p.vehicle, p.result
            h = v.model.plant.h
            self.send(self.decoder.encode_command(addr, Command(v.sysid, r.k, float(r.u[0])), h), addr)
            self.commands_sent += 1
            raised = v.alarm.raised
            if self.publisher is not None:
                self.publisher.estimate((v.sysid, r.k, p.t, r.f_hat, r.x_hat, r.residual, r.u, p.tau_obs, raised))
                if p.alarm_event is not None:
                    self.publisher.alarm(v.sysid, r.k, p.t, p.alarm_event, r.f_hat)
            if p.alarm_event is not None:
                log.info("vehicle %d: alarm %s at k=%d (|f_hat| = %.3g %s)", v.sysid, p.alarm_event, r.k, p.f_mag,
                         v.model.plant.unit)
            processing = (time.perf_counter_ns() - t0_ns) * 1e-9
            self.processing_s.append(processing)
            if self.recorder is not None:
                self.recorder.submit(SampleRecord(
                    sysid=v.sysid, k=r.k, t=p.t, wall=wall, y=[c0 * tel.alpha_deg + c1 * tel.q_deg_s
                                                             for c0, c1 in v.model.C_rows],
                    alpha=tel.alpha_deg, q=tel.q_deg_s, elevator=tel.elevator_deg, x_hat=r.x_hat.tolist(),
                    f_hat=r.f_hat.tolist(), u=r.u.tolist(), residual=r.residual.tolist(), tau_obs=p.tau_obs,
                    processing_s=processing, alarm=raised))

    def on_truth(self, payload: bytes) -> None:
        """A ``<prefix>/<sysid>/truth`` sample from the simulator, recorded next to the estimates."""
        if self.recorder is None:
            return
        try:
            d = json.loads(payload)
            self.recorder.submit_truth(TruthRecord(sysid=int(d["sysid"]), k=int(d["k"]), t=float(d["t"]),
                                                   x=list(d["x"]), f=list(d["f"]), d=list(d.get("d") or []),
                                                   tau=d.get("tau")))
        except Exception as exc:  # someone else's bad payload is not our crash
            log.debug("ignoring a truth sample: %s", exc)

    def housekeeping(self) -> None:
        now = time.monotonic()
        self.table.expire(now)
        self.decoder.evict(now)
        self.decoder.bump_signing_clocks()

    def summary(self) -> str:
        t, c = self.table.counters, self.decoder.counters
        p50, p99 = percentile(self.processing_s, 50), percentile(self.processing_s, 99)
        timing = (f"processing p50 {p50 * 1e6:.0f} us, p99 {p99 * 1e6:.0f} us" if p50 is not None
                  else "no processing times")
        published = ""
        if self.publisher is not None:
            published = f", published {self.publisher.published}, publish drops {self.publisher.dropped}"
        return (f"samples processed {t.processed}, duplicates {t.duplicates}, stale {t.stale}, "
                f"garbage {c.garbage}, truncated {c.truncated}, bad signature {c.bad_signature}, "
                f"wrong dialect {c.wrong_dialect}, foreign {c.foreign}, incomplete {c.incomplete}, "
                f"refused {t.refused}, skipped {t.skipped}, vehicles {t.vehicles_seen}, restarts {t.restarts}, "
                f"commands {self.commands_sent}{published}; {timing}")


def _open_recorder(config: MonitorConfig):
    if not config.rrd:
        return None
    from monitor.service.recorder import RrdRecorder

    return RrdRecorder(config.rrd, properties=config.rrd_properties)


async def _serve(config: MonitorConfig, monitor: Monitor) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    transport, endpoint = await loop.create_datagram_endpoint(
        lambda: UdpEndpoint(monitor.on_datagram), local_addr=(config.host, config.port))
    monitor.send = endpoint.send
    log.info("ready: MAVLink udpin:%s:%d, Zenoh key prefix '%s', name '%s'%s", config.host,
             transport.get_extra_info("sockname")[1], config.prefix, config.name,
             f", recording {config.rrd}" if config.rrd else "")
    try:
        while not stop.is_set():
            try:
                await asyncio.wait_for(stop.wait(), timeout=1.0)
            except asyncio.TimeoutError:
                monitor.housekeeping()
    finally:
        transport.close()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
            signal.signal(sig, signal.SIG_IGN)  # a second signal must not cut the flush short


def run_daemon(config: MonitorConfig, zenoh_config) -> int:
    """Run until SIGINT/SIGTERM; returns the exit code (0)."""
    from monitor.service.publisher import EstimatePublisher
    from monitor.wire.zenoh_session import close_quietly, open_session

    session = open_session(zenoh_config)
    publisher = truth_sub = recorder = None
    try:
        recorder = _open_recorder(config)
        units = {m.plant.unit for m in [config.fleet.default, *config.fleet.by_sysid.values()] if m is not None}
        publisher = EstimatePublisher(session, config.prefix, config.name, unit=next(iter(units), "deg"),
                                      queue_max=config.queue_max)
        monitor = Monitor(config, send=lambda data, addr: None, publisher=publisher, recorder=recorder)
        if config.truth and recorder is not None:
            truth_sub = session.declare_subscriber(f"{config.prefix.rstrip('/')}/*/truth",
                                                   lambda sample: monitor.on_truth(sample.payload.to_bytes()))
        asyncio.run(_serve(config, monitor))
        log.info("stopped: %s", monitor.summary())
    finally:
        close_quietly(None, truth_sub)  # no truth callback may reach a closed recorder
        entities: list[Any] = publisher.close() if publisher is not None else []
        if recorder is not None:
            recorder.close()
        close_quietly(session, *entities)
    return 0
