"""A flight's samples read from a telemetry log, as ``analyse`` assembles them, with no estimator behind.

Why its own module: ``identify`` (and the aircraft demo, which identifies from the log it recorded) need the
samples and what the log held, not the observer ``service/offline.py`` runs over them. The chain is the link
layer's: ``read_tlog`` -> ``FrameParser`` -> the dialect's layouts -> the signal map -> ``SampleAssembler``
(observe-only: a sample needs its actuator report). The same pass fills the log's inventory
(``monitor.link.log_inventory``: what the log holds, for the report and for the error when a signal is missing).
"""

from __future__ import annotations

import itertools
import math
import os
import time
from collections.abc import Callable

from monitor.link.log_inventory import LogInventory

__all__ = ["FlightLog", "log_spacing", "read_flight"]

_PROBE_INSTANTS = 400  # instant messages looked at to find the log's sample spacing


class FlightLog:
    """What ``read_flight`` found: per system id the samples (k, values), and what was seen."""

    def __init__(self) -> None:
        self.samples: dict[int, list[tuple[int, dict[str, float]]]] = {}
        self.seen: dict[int, dict[str, int]] = {}
        self.records = 0
        self.skipped_bytes = 0
        self.truncated = False
        self.counters: dict[str, int] = {}
        self.inventory = LogInventory()


def log_spacing(path: str, instant: str, sysid: int | None) -> float | None:
    """The median spacing of the instant message's ``time_usec`` over the first few hundred (s), or None."""
    from monitor.link.dialect import layout_by_name
    from monitor.link.frames import FrameCounters, FrameParser
    from monitor.link.tlog import read_tlog

    layout = layout_by_name(instant)
    if layout is None or layout.time_field() is None:
        return None
    pos = layout.position(layout.time_field()[0])
    unit = layout.time_field()[1]
    parser = FrameParser(FrameCounters())
    stamps: list[int] = []
    for _t, frame in read_tlog(path):
        for msgid, sys_, _c, payload in parser.feed(frame):
            if msgid == layout.msgid and (sysid is None or sys_ == sysid):
                stamps.append(int(layout.decode(payload)[pos]) * unit)
        if len(stamps) >= _PROBE_INSTANTS:
            break
    steps = sorted(b - a for a, b in itertools.pairwise(stamps) if b > a)
    if not steps:
        return None
    return steps[len(steps) // 2] / 1e6


def read_flight(path: str, smap, h: float, sysid: int | None = None,
                progress: Callable[[float, int], None] | None = None, progress_every_s: float = 2.0) -> FlightLog:
    """Every sample of every vehicle (only ``sysid``'s if given), assembled as ``analyse`` assembles them."""
    from monitor.link.assembly import SampleAssembler
    from monitor.link.dialect import layout_by_name
    from monitor.link.frames import FrameCounters, FrameParser
    from monitor.link.tlog import TlogStats, read_tlog

    wanted = {}
    for name in {smap.instant, *(s.message for s in smap.measured.values())}:
        layout = layout_by_name(name)
        wanted[layout.msgid] = (layout.name, layout)
    counters = FrameCounters()
    parser = FrameParser(counters)
    stats = TlogStats()
    out = FlightLog()
    assemblers: dict[int, SampleAssembler] = {}
    size = max(os.path.getsize(path), 1)
    position = 0
    start = time.perf_counter()
    next_report = start + progress_every_s

    def keep(sys_: int, ready) -> None:
        out.samples.setdefault(sys_, []).extend((sample.k, sample.values) for sample in ready)

    add = out.inventory.add_frames
    for t_us, frame in read_tlog(path, stats):
        position += 8 + len(frame)
        v1 = counters.frames_v1
        frames = parser.feed(frame)
        add(t_us, frames, counters.frames_v1 - v1)
        for msgid, sys_, _compid, payload in frames:
            entry = wanted.get(msgid)
            if entry is None or (sysid is not None and sys_ != sysid):
                continue
            name, layout = entry
            seen = out.seen.setdefault(sys_, {})
            seen[name] = seen.get(name, 0) + 1
            values = layout.decode(payload)
            asm = assemblers.get(sys_)
            if asm is None:
                asm = assemblers[sys_] = SampleAssembler(smap, h, observe=True)
            if asm.uses(name):
                keep(sys_, asm.add(name, values, None, t_us * 1e-6))
        if progress is not None and stats.records % 4096 == 0 and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + progress_every_s
            progress(position / size, sum(len(v) for v in out.samples.values()))
    for sys_, asm in assemblers.items():
        keep(sys_, asm.flush(math.inf))
    out.records, out.skipped_bytes, out.truncated = stats.records, stats.skipped_bytes, stats.truncated
    totals: dict[str, int] = counters.as_dict()
    for asm in assemblers.values():
        for key, value in asm.counters.as_dict().items():
            totals[key] = totals.get(key, 0) + value
    out.counters = totals
    return out
