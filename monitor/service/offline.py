"""Observe-only estimation over a MAVLink telemetry log: the live pipeline, fed from a file.

The same ``FrameParser`` (one per record: a tlog record holds one whole frame), the same assembler,
vehicle table and estimator as ``fault-monitor run --observe``; ``now`` and ``wall`` are the log's own
timestamps, so the assembler's bounded waits and the observed delay mean what they meant in flight.
Nothing is sent. Samples go to an in-memory list (for the report, which is ``replay``'s) and, with
``--rrd``, to the same recorder and layout as ``run``. The same pass fills the log's inventory (what it holds:
``monitor.link.log_inventory``), which the report prints and a log that gives no sample is explained with.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.link.frames import FrameParser
from monitor.link.log_inventory import LogInventory
from monitor.link.tlog import TlogStats, read_tlog
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import EnvelopeModel, Fleet
from monitor.service.pipeline import Pipeline
from monitor.service.records import SampleRecord
from monitor.service.vehicles import VehicleTable

__all__ = ["LogAnalysis", "analyse_log", "analyse_dataflash", "envelope_report", "envelope_lines"]

log = logging.getLogger("monitor.analyse")

_COMMAND_ID = 139  # SET_ACTUATOR_CONTROL_TARGET: a monitor flew this vehicle


class _Collect:
    """The recorder interface: keep every record, and forward to a real recorder when there is one."""

    def __init__(self, forward=None) -> None:
        self.records: list[SampleRecord] = []
        self.forward = forward

    def submit(self, record: SampleRecord) -> None:
        self.records.append(record)
        if self.forward is not None:
            self.forward.submit(record)


@dataclass
class LogAnalysis:
    records: list[SampleRecord]
    counts: dict[str, int]
    log_records: int
    skipped_bytes: int
    truncated: bool
    seconds: float
    first_t_us: int | None = None
    last_t_us: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    inventory: LogInventory = field(default_factory=LogInventory)


def analyse_log(
    path: str | Path,
    fleet: Fleet,
    alarm: AlarmConfig,
    sysid: int | None = None,
    recorder=None,
    progress: Callable[[float, int], None] | None = None,
    progress_every_s: float = 2.0,
) -> LogAnalysis:
    """Run the observer over every sample of the log (only ``sysid``'s if given)."""
    start = time.perf_counter()
    table = VehicleTable(fleet, alarm, timeout=float("inf"), observe=True)
    collect = _Collect(recorder)
    pipeline = Pipeline(table, send_commands=False, gcs_feedback=False, recorder=collect)
    parser = FrameParser(pipeline.frames)
    stats = TlogStats()
    size = max(Path(path).stat().st_size, 1) if Path(path).exists() else 1
    first = last = None
    next_report = start + progress_every_s
    position = 0
    feed, on_frames, perf_ns = parser.feed, pipeline.on_frames, time.perf_counter_ns
    commands = 0
    counters, inventory = pipeline.frames, LogInventory()
    add = inventory.add_frames
    for t_us, frame in read_tlog(path, stats):
        if first is None:
            first = t_us
        last = t_us
        position += 8 + len(frame)
        v1 = counters.frames_v1
        frames = feed(frame)
        add(t_us, frames, counters.frames_v1 - v1)
        if not frames:
            continue
        if frames[0][0] == _COMMAND_ID:
            commands += 1
        if sysid is not None:
            frames = [f for f in frames if f[1] == sysid]
            if not frames:
                continue
        t = t_us * 1e-6
        on_frames(None, frames, perf_ns(), now=t, wall=t)
        if progress is not None and stats.records % 4096 == 0:
            now = time.perf_counter()
            if now >= next_report:
                next_report = now + progress_every_s
                progress(position / size, len(collect.records))
    if last is not None:
        pipeline.flush(last * 1e-6, last * 1e-6)
    return LogAnalysis(
        collect.records,
        pipeline.counts(),
        stats.records,
        stats.skipped_bytes,
        stats.truncated,
        time.perf_counter() - start,
        first,
        last,
        {"commands_in_log": commands},
        inventory,
    )


def analyse_dataflash(
    dlog,
    fleet: Fleet,
    alarm: AlarmConfig,
    sysid: int | None = None,
    recorder=None,
    progress: Callable[[float, int], None] | None = None,
    progress_every_s: float = 2.0,
) -> LogAnalysis:
    """The same observer over an ArduPilot DataFlash log (``monitor.link.dataflash.DataFlashLog``): its records
    of the messages the signal maps name, by name, with TimeUS as the clock; one vehicle (sysid 1 or ``sysid``)."""
    from monitor.link.dataflash import DATAFLASH_SYSID, wanted_fields

    start = time.perf_counter()
    table = VehicleTable(fleet, alarm, timeout=float("inf"), observe=True)
    collect = _Collect(recorder)
    pipeline = Pipeline(table, send_commands=False, gcs_feedback=False, recorder=collect)
    wanted: dict[str, set[str]] = {}
    for model in fleet.models():
        for name, cols in wanted_fields(model.signals, dlog.layouts).items():
            wanted.setdefault(name, set()).update(cols)
    label = sysid if sysid is not None else DATAFLASH_SYSID
    total = max(sum(dlog.counts.get(n, 0) for n in wanted), 1)
    first = last = None
    next_report = start + progress_every_s
    on_message = pipeline.on_message
    for n, (name, values, t_us) in enumerate(dlog.records(wanted), 1):
        if first is None:
            first = t_us
        last = t_us
        t = t_us * 1e-6
        on_message(label, name, values, t, t)
        if progress is not None and n % 4096 == 0 and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + progress_every_s
            progress(n / total, len(collect.records))
    if last is not None:
        pipeline.flush(last * 1e-6, last * 1e-6)
    return LogAnalysis(
        collect.records,
        pipeline.counts(),
        dlog.inventory.records,
        0,
        False,
        time.perf_counter() - start,
        first,
        last,
        {"dataflash_records_read": dlog.records_read},
        dlog.inventory,
    )


def envelope_report(env: EnvelopeModel, records: list[SampleRecord]) -> dict[str, Any]:
    """Per point of an envelope model: how many samples it estimated and how many of those were outside the
    identified range (alarms paused); with the schedule and each point's place. Every vehicle of ``records``."""
    used = [0] * len(env.points)
    outside = [0] * len(env.points)
    for r in records:
        if r.point is None:
            continue
        used[r.point] += 1
        outside[r.point] += r.inside is False
    names = env.envelope.schedule
    return {
        "name": env.envelope.name,
        "schedule": list(names),
        "units": [env.unit(n) for n in names],
        "points": [
            {"name": p.name, "at": p.at, "samples": used[i], "outside": outside[i]}
            for i, p in enumerate(env.envelope.points)
        ],
        "samples": sum(used),
        "outside": sum(outside),
    }


def envelope_lines(report: dict[str, Any]) -> list[str]:
    """``envelope_report`` as the text report's lines: one per point."""
    lines = [
        f"envelope {report['name']} scheduled by {', '.join(report['schedule'])}: {report['samples']} samples, "
        f"{report['outside']} outside the identified range (alarms paused)"
    ]
    width = max(len(p["name"]) for p in report["points"])
    for p in report["points"]:
        place = ", ".join(
            f"{n} {p['at'][n]:g}" + (f" {u}" if u else "")
            for n, u in zip(report["schedule"], report["units"], strict=True)
        )
        lines.append(f"  point {p['name']:<{width}}  ({place}): {p['samples']} samples, {p['outside']} outside")
    return lines
