"""The monitor daemon: opens the links, Zenoh and the recorder around one ``Pipeline`` and one asyncio loop.

The hot path is synchronous inside the links' read callbacks (``Pipeline.on_reads``: a link drains its socket
and hands every read over at once; the pipeline answers each vehicle's newest sample within a round's budget and,
when samples are left, the loop calls it again at once, after the links had their turn). Beside it the loop runs
two timers: while vehicles are known, every ``poll_s`` (5 ms) samples whose bounded wait for an actuator report
ran out are processed, and once a second the housekeeping: heartbeats on every link, vehicle expiry, the WARNING
for a vehicle whose telemetry never becomes a sample, the end of an overload episode, and the one WARNING when a
signed link refuses MAVLink 1 frames.

Why nothing else wakes: an idle monitor (no vehicle) runs the 1 Hz housekeeping only, and the Zenoh and recorder
threads sleep until there is something to write (``benchmarks/bench_idle.py``: under 1 % of a core).

Shutdown (SIGINT/SIGTERM): stop reading, log the summary, drain the Zenoh queue (bounded), close the
recorder (which flushes and writes the footer; live viewers get a bounded wait), undeclare everything and close the
session (bounded), exit 0. A second signal during shutdown is ignored rather than leaving a half-written recording.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import signal
import socket
import sys
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from monitor.link.signing import Signer
from monitor.link.transports import ConnectionSpec, Link, UdpLink, open_link
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet
from monitor.service.pipeline import Pipeline
from monitor.service.records import TruthRecord
from monitor.service.vehicles import VehicleTable

if TYPE_CHECKING:
    from monitor.service.group_link import GroupLink  # imported where a group is joined: it imports zenoh

__all__ = ["MonitorConfig", "build_pipeline", "run_daemon", "default_name"]

log = logging.getLogger("monitor.run")

SWITCH_INTERVAL_S = 0.0005
LATE_TICK_S = 0.25  # a housekeeping tick this late: the loop was not running


def default_name() -> str:
    """``<host>-<pid>``: unique per process, readable in the liveliness key."""
    host = "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in socket.gethostname()) or "host"
    return f"{host}-{os.getpid()}"


@dataclass
class MonitorConfig:
    fleet: Fleet
    connections: list[ConnectionSpec]
    prefix: str = "uav"
    name: str = field(default_factory=default_name)
    rrd: str | None = None
    rrd_properties: dict[str, Any] = field(default_factory=dict)
    signing_key: bytes | None = None
    alarm: AlarmConfig = field(default_factory=AlarmConfig)
    vehicle_timeout: float = 10.0
    truth: bool = True
    queue_max: int = 10_000
    observe: bool = False
    compensate: bool = False  # the vehicle's autopilot flies; the monitor sends the fault compensation alone
    gcs_feedback: bool = True
    assembly_wait: float = 0.02
    zenoh_endpoints: str = ""
    poll_s: float = 0.005
    live_urls: list[str] = field(default_factory=list)  # live Rerun viewers' gRPC addresses (--rerun-url)
    group: str | None = None  # a monitor group's name (--group): each vehicle answered by one member
    spawn_viewer: str | None = None  # the `rerun` executable to start a local viewer with (--rerun-spawn)


def build_pipeline(config: MonitorConfig, publisher=None, recorder=None) -> Pipeline:
    table = VehicleTable(
        config.fleet,
        config.alarm,
        config.vehicle_timeout,
        observe=config.observe,
        wait_s=config.assembly_wait,
        compensate=config.compensate,
    )
    return Pipeline(table, gcs_feedback=config.gcs_feedback, publisher=publisher, recorder=recorder)


def _on_truth(recorder, payload: bytes) -> None:
    """A ``<prefix>/<sysid>/truth`` sample from the simulator, recorded next to the estimates."""
    try:
        d = json.loads(payload)
        recorder.submit_truth(
            TruthRecord(
                sysid=int(d["sysid"]),
                k=int(d["k"]),
                t=float(d["t"]),
                x=list(d["x"]),
                f=list(d["f"]),
                d=list(d.get("d") or []),
                tau=d.get("tau"),
            )
        )
    except Exception as exc:  # someone else's bad payload is not our crash
        log.debug("ignoring a truth sample: %s", exc)


def _check_recorder(pipeline: Pipeline) -> None:
    """A recording that stopped being written is an ERROR now (logged by the recorder) and in the status."""
    recorder, publisher = pipeline.recorder, pipeline.publisher
    if recorder is not None and getattr(recorder, "error", None) and publisher is not None:
        publisher.status_extra["recording_error"] = recorder.error


def _recording_outputs(config: MonitorConfig) -> str:
    """The ready line's tail: where the samples go besides Zenoh (a file, live viewers)."""
    out = f", recording {config.rrd}" if config.rrd else ""
    return out + "".join(f", live viewer {url}" for url in config.live_urls)


def _operating_points(config: MonitorConfig) -> str:
    """The ready line's last part: the operating point of each model that has one (plants from ``identify``), and
    an envelope's name, schedule and points."""
    models = config.fleet.models()
    parts = []
    for m in models:
        text = m.envelope.describe() if m.envelope is not None else m.signals.describe_operating_point()
        if text is not None:
            parts.append(text if len(models) == 1 else f"plant {m.name}: {text}")
    return "".join(f"; {part}" for part in parts)


def _live_urls(config: MonitorConfig) -> list[str]:
    """``--rerun-url`` addresses plus the spawned viewer's (started here, before the loop), each once."""
    urls = list(dict.fromkeys(config.live_urls))
    if config.spawn_viewer:
        from monitor.service.live_sinks import spawn_viewer

        url = spawn_viewer(config.spawn_viewer)
        urls += [url] if url not in urls else []
    return urls


class _Timers:
    """The loop's timed work, all of it event-driven: the next round when one was left over, the assembler's poll
    while vehicles are known, and the 1 Hz housekeeping."""

    def __init__(self, loop: asyncio.AbstractEventLoop, config: MonitorConfig, pipeline: Pipeline, links: list[Link]):
        self.loop = loop
        self.config = config
        self.pipeline = pipeline
        self.links = links
        self._round: asyncio.Handle | None = None
        self._poll: asyncio.TimerHandle | None = None
        self._housekeeping: asyncio.TimerHandle | None = None

    def on_reads(self, reads) -> None:
        """A link's reads: answered at once; what the round's budget left is answered in the next pass of the loop
        (after the links were drained again: a newer sample of the same vehicle replaces the older one)."""
        self.pipeline.on_reads(reads)
        self._after_round()

    def _next_round(self) -> None:
        self._round = None
        self.pipeline.answer()
        self._after_round()

    def _after_round(self) -> None:
        if self._round is None and self.pipeline.pending():
            self._round = self.loop.call_soon(self._next_round)
        if self._poll is None and self.pipeline.table.vehicles:
            self._poll = self.loop.call_later(self.config.poll_s, self._polling)

    def _polling(self) -> None:
        """Samples whose wait for an actuator report ran out; ticks only while vehicles are known."""
        self.pipeline.poll(time.monotonic())
        self._poll = self.loop.call_later(self.config.poll_s, self._polling) if self.pipeline.table.vehicles else None

    def start(self) -> None:
        for link in self.links:
            link.heartbeat()
        self._housekeeping = self.loop.call_at(self.loop.time() + 1.0, self._housekeep)

    def _housekeep(self) -> None:
        now = time.monotonic()
        # a tick far behind its time: the loop could not run (stopped, starved), and what queued meanwhile is not
        # read yet: the overload episode is not judged on it
        late = self.loop.time() - self._housekeeping.when() > LATE_TICK_S if self._housekeeping else False
        pipeline = self.pipeline
        for link in self.links:
            link.heartbeat()
        pipeline.table.expire(now)
        pipeline.table.warn_missing(now)
        pipeline.warn_frames()
        if not late:
            pipeline.check_overload()
        _check_recorder(pipeline)
        self._housekeeping = self.loop.call_at(self.loop.time() + 1.0, self._housekeep)

    def cancel(self) -> None:
        for handle in (self._round, self._poll, self._housekeeping):
            if handle is not None:
                handle.cancel()


async def _serve(config: MonitorConfig, pipeline: Pipeline, group: GroupLink | None = None) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    signer = Signer(config.signing_key) if config.signing_key is not None else None
    links: list[Link] = []
    timers = _Timers(loop, config, pipeline, links)
    try:
        if group is not None:  # listening to the group before the first sample can be asked whether to answer it
            group.start(loop)
        for i, spec in enumerate(config.connections):
            link = open_link(spec, i, timers.on_reads, pipeline.frames, signer)
            if isinstance(link, UdpLink):
                link.stale_ns, link.on_stale = int(pipeline.deadline_s * 1e9), pipeline.on_stale
            await link.start()
            links.append(link)
        mode = "compensation only" if config.compensate else "observe-only" if config.observe else "closed loop"
        log.info(
            "ready: %s; MAVLink %s; Zenoh %s, key prefix '%s', name '%s'%s%s%s",
            mode,
            ", ".join(link.local for link in links),
            config.zenoh_endpoints or "(config file)",
            config.prefix,
            config.name,
            f", group '{config.group}'" if config.group else "",
            _recording_outputs(config),
            _operating_points(config),
        )
        timers.start()
        await stop.wait()
    finally:
        if group is not None:
            group.stop()
        timers.cancel()
        for link in links:
            link.close()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
            signal.signal(sig, signal.SIG_IGN)  # a second signal must not cut the flush short


def run_daemon(config: MonitorConfig, zenoh_config) -> int:
    """Run until SIGINT/SIGTERM; returns the exit code: 0, or 1 when the recording could not be written."""
    from monitor.service.publisher import EstimatePublisher
    from monitor.wire.zenoh_session import close_quietly, open_session

    # the Zenoh and recorder threads share the GIL with the loop: a short switch interval bounds how long
    # a datagram waits behind them (Python's default 5 ms would be a quarter of a 50 Hz sample period)
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    session = open_session(zenoh_config)
    publisher = truth_sub = recorder = group = None
    try:
        config.live_urls = _live_urls(config)
        if config.rrd or config.live_urls:
            from monitor.service.recorder import RrdRecorder

            recorder = RrdRecorder(config.rrd, properties=config.rrd_properties, live=config.live_urls)
        units = {m.plant.unit for m in config.fleet.models()}
        publisher = EstimatePublisher(
            session,
            config.prefix,
            config.name,
            unit=next(iter(units), "deg"),
            queue_max=config.queue_max,
            member=config.name if config.group else None,
        )
        pipeline = build_pipeline(config, publisher, recorder)
        if config.group:
            from monitor.service.group import GroupView
            from monitor.service.group_link import GroupLink

            pipeline.group = GroupView(config.name, config.prefix, now=time.monotonic())
            group = GroupLink(session, config.prefix, config.group, pipeline.group, pipeline.table)
        if config.truth and recorder is not None:
            rec = recorder
            truth_sub = session.declare_subscriber(
                f"{config.prefix.rstrip('/')}/*/truth", lambda sample: _on_truth(rec, sample.payload.to_bytes())
            )
        asyncio.run(_serve(config, pipeline, group))
        log.info("stopped: %s", pipeline.summary())
    finally:
        close_quietly(None, truth_sub)  # no truth callback may reach a closed recorder
        if group is not None:
            close_quietly(None, *group.close())
        entities: list[Any] = publisher.close() if publisher is not None else []
        if recorder is not None:
            recorder.close()
        close_quietly(session, *entities)
    if recorder is not None and recorder.error:
        log.error("the recording %s is incomplete: %s", config.rrd, recorder.error)
        return 1
    return 0
