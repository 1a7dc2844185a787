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


def log_spacing(path: str, instant: str, sysid: int | None, dataflash=None) -> float | None:
    """The median spacing of the instant message's ``time_usec`` over the first few hundred (s), or None.

    ``dataflash``: the opened DataFlash log ``path`` is (``monitor.link.dataflash``): its instant's TimeUS."""
    stamps: list[int] = []
    if dataflash is not None:
        layout = dataflash.layouts(instant)
        stamp = layout.time_field() if layout is not None else None
        if stamp is None:
            return None
        for _name, _values, t_us in dataflash.records({instant: {stamp[0]}}):
            stamps.append(t_us)
            if len(stamps) >= _PROBE_INSTANTS:
                break
    else:
        from monitor.link.dialect import layout_by_name
        from monitor.link.frames import FrameCounters, FrameParser
        from monitor.link.tlog import read_tlog

        layout = layout_by_name(instant)
        stamp = layout.time_field() if layout is not None else None
        if layout is None or stamp is None:
            return None
        pos = layout.position(stamp[0])
        unit = stamp[1]
        parser = FrameParser(FrameCounters())
        for _t, frame in read_tlog(path):
            for msgid, sys_, _c, payload in parser.feed(frame):
                if msgid == layout.msgid and (sysid is None or sys_ == sysid):
                    stamps.append(int(layout.decode(payload)[pos]) * unit)
            if len(stamps) >= _PROBE_INSTANTS:
                break
    return _spacing(stamps)


def _spacing(stamps: list[int]) -> float | None:
    """The sample spacing (s) of instant stamps (us): the median step, refined by a least-squares line through
    the stamps against their step counts, rounded to 10 us.

    Why not the median alone: a real autopilot stamps each message a few ms off its sample's instant, and the
    median of 400 jittered steps is off by ~1 % (0-8 ms jitter at 20 ms: 19.88 ms measured), which then makes
    ``k`` slip against the log's own clock. The line uses every stamp (and skips over gaps of lost samples)."""
    steps = sorted(b - a for a, b in itertools.pairwise(stamps) if b > a)
    if not steps:
        return None
    median = steps[len(steps) // 2]
    t0, count_steps = stamps[0], 0
    pairs = [(0, 0)]
    for a, b in itertools.pairwise(stamps):  # step by step: a median 1 % off must not slip the count
        step = round((b - a) / median)
        if step < 1:  # a repeated or reordered stamp
            continue
        count_steps += step
        pairs.append((count_steps, b - t0))
    count = len(pairs)
    mean_i = sum(i for i, _ in pairs) / count
    mean_t = sum(t for _, t in pairs) / count
    var = sum((i - mean_i) ** 2 for i, _ in pairs)
    if var <= 0:
        return median / 1e6
    slope = sum((i - mean_i) * (t - mean_t) for i, t in pairs) / var
    if not 0.5 * median < slope < 1.5 * median:
        return median / 1e6
    return round(slope / 1e6, 5)


def read_flight(
    path: str,
    smap,
    h: float,
    sysid: int | None = None,
    progress: Callable[[float, int], None] | None = None,
    progress_every_s: float = 2.0,
    dataflash=None,
) -> FlightLog:
    """Every sample of every vehicle (only ``sysid``'s if given), assembled as ``analyse`` assembles them.

    ``dataflash``: the opened DataFlash log ``path`` is: its records by name, one vehicle (sysid 1 or ``sysid``)."""
    if dataflash is not None:
        return _read_dataflash_flight(dataflash, smap, h, sysid, progress, progress_every_s)
    from monitor.link.assembly import SampleAssembler
    from monitor.link.dialect import layout_by_name
    from monitor.link.frames import FrameCounters, FrameParser
    from monitor.link.tlog import TlogStats, read_tlog

    wanted = {}
    for name in {smap.instant, *(s.message for s in smap.raw.values())}:
        layout = layout_by_name(name)
        if layout is not None:  # a MAVLink map (parse_signals checked its names): always found
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


def _read_dataflash_flight(dlog, smap, h: float, sysid: int | None, progress, progress_every_s: float) -> FlightLog:
    """``read_flight`` for a DataFlash log: the same assembler, fed (name, values, TimeUS) by the log's records."""
    from monitor.link.assembly import SampleAssembler
    from monitor.link.dataflash import DATAFLASH_SYSID, wanted_fields

    label = sysid if sysid is not None else DATAFLASH_SYSID
    out = FlightLog()
    out.inventory = dlog.inventory
    asm = SampleAssembler(smap, h, observe=True)
    rows = out.samples.setdefault(label, [])
    seen = out.seen.setdefault(label, {})
    wanted = wanted_fields(smap, dlog.layouts)
    total = max(sum(dlog.counts.get(n, 0) for n in wanted), 1)
    next_report = time.perf_counter() + progress_every_s
    for n, (name, values, t_us) in enumerate(dlog.records(wanted), 1):
        seen[name] = seen.get(name, 0) + 1
        if asm.uses(name):
            rows.extend((s.k, s.values) for s in asm.add(name, values, None, t_us * 1e-6))
        if progress is not None and n % 4096 == 0 and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + progress_every_s
            progress(n / total, len(rows))
    rows.extend((s.k, s.values) for s in asm.flush(math.inf))
    if not rows:
        del out.samples[label]
    if not seen:
        del out.seen[label]
    out.records = dlog.inventory.records
    out.counters = asm.counters.as_dict()
    return out
