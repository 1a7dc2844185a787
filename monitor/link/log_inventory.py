"""What a flight log holds, in one pass: records, MAVLink 1/2 frames, each message with its rate, system ids.

Why: the commonest reason a log gives no sample is a good log read with a signal map for messages it does
not have (a MAVLink 1 log has no ``AOA_SSA``; an ArduCopter sends ``SERVO_OUTPUT_RAW``, not
``ACTUATOR_OUTPUT_STATUS``). Saying what the log holds, and which of its messages could carry each missing
signal, turns "no sample" into a signal map the user can write. ``analyse`` and ``identify`` feed the
inventory from the pass they make anyway (``add_frames``, per record), so it costs no second read;
``read_inventory`` is the same pass on its own. DataFlash logs fill the same inventory by message name (no
system ids, no MAVLink version), from their reader's per-message counts (``add_counts``); so do ULog logs
(PX4), by topic instance (``actuator_outputs[1]``), with the log's dropouts.

Rates are counts over the log's time span (first to last record time stamp), so a message sent in bursts
or only part of the flight shows its average, not its peak.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.link.dialect import layout_by_id, layout_by_name
from monitor.link.frames import RawFrame

__all__ = [
    "LogInventory",
    "MessageStats",
    "read_inventory",
    "SIGNAL_KINDS",
    "explain_missing",
    "why_no_samples",
    "field_ref",
]

# What a signal is, and the messages (MAVLink, then DataFlash) a log may carry it in: the hint a user needs
# to write a signal map from the log's own messages.
SIGNAL_KINDS: dict[str, tuple[str, ...]] = {
    "angle of attack": ("AOA_SSA", "AOA"),
    "attitude": (
        "ATTITUDE",
        "ATTITUDE_QUATERNION",
        "AHRS2",
        "AHRS3",
        "SIMSTATE",
        "SIM_STATE",
        "HIL_STATE",
        "HIL_STATE_QUATERNION",
        "ATT",
        "AHR2",
        "CTUN",
        "SIM",
        "vehicle_attitude",
        "vehicle_attitude_groundtruth",
    ),
    "body rates (gyro)": (
        "ATTITUDE",
        "RAW_IMU",
        "SCALED_IMU",
        "SCALED_IMU2",
        "SCALED_IMU3",
        "HIGHRES_IMU",
        "HIL_STATE",
        "RATE",
        "PIDP",
        "IMU",
        "GYR",
        "vehicle_angular_velocity",
        "sensor_combined",
    ),
    "airspeed": (
        "VFR_HUD",
        "AIRSPEED",
        "SCALED_PRESSURE",
        "HIL_STATE",
        "ARSP",
        "CTUN",
        "airspeed_validated",
        "airspeed",
    ),
    "velocity (for a derived angle of attack)": (
        "LOCAL_POSITION_NED",
        "GLOBAL_POSITION_INT",
        "HIL_STATE_QUATERNION",
        "NKF1",
        "XKF1",
        "vehicle_local_position",
        "vehicle_local_position_groundtruth",
    ),
    "actuator output": (
        "ACTUATOR_OUTPUT_STATUS",
        "SERVO_OUTPUT_RAW",
        "HIL_ACTUATOR_CONTROLS",
        "ACTUATOR_CONTROL_TARGET",
        "HIL_CONTROLS",
        "RCOU",
        "CTUN",
        "actuator_servos",
        "actuator_outputs",
        "actuator_controls_0",
    ),
}
_KIND_BY_SIGNAL_NAME = {
    "alpha": ("angle of attack",),
    "aoa": ("angle of attack",),
    "q": ("body rates (gyro)",),
    "pitch_rate": ("body rates (gyro)",),
    "theta": ("attitude",),
    "pitch": ("attitude",),
    "airspeed": ("airspeed",),
    "elevator": ("actuator output",),
}
_LIST_MESSAGES = 12  # messages named in the human summary (the JSON has them all)


@dataclass
class MessageStats:
    name: str
    msgid: int | None  # MAVLink id, or the DataFlash format type
    count: int = 0
    sysids: set[int] = field(default_factory=set)


class LogInventory:
    """Counts of one log: records, frames by MAVLink version, per (system id, message), time span."""

    def __init__(self, kind: str = "tlog") -> None:
        self.kind = kind  # "tlog", "dataflash" or "ulog"
        self.dropouts = 0  # a ULog log's dropout markers (the logger lost data there)
        self.records = 0
        self.frames_v1 = 0
        self.frames_v2 = 0
        self.first_us: int | None = None
        self.last_us: int | None = None
        self._counts: dict[tuple[int, int | str], int] = {}  # (sysid, msgid or DataFlash name) -> count
        self._timed: set[str] = set()  # DataFlash messages with a TimeUS

    # --- filling ---------------------------------------------------------------------------------------
    def add_frames(self, t_us: int, frames: Sequence[RawFrame], v1: int = 0) -> None:
        """One tlog record: its time stamp and the frames parsed from it (``v1`` of them in MAVLink 1)."""
        self.records += 1
        if self.first_us is None:
            self.first_us = t_us
        self.last_us = t_us
        counts = self._counts
        for msgid, sysid, _compid, _payload in frames:
            key = (sysid, msgid)
            counts[key] = counts.get(key, 0) + 1
        self.frames_v1 += v1
        self.frames_v2 += len(frames) - v1

    def add_counts(self, name: str, count: int, first_us: int | None, last_us: int | None) -> None:
        """A DataFlash message (a ULog topic instance): how many records of it, and the TimeUS (timestamp) of its
        first and last (None: no time)."""
        self.records += count
        for t_us in (first_us, last_us):
            if t_us is None:
                continue
            self._timed.add(name)
            if self.first_us is None or t_us < self.first_us:
                self.first_us = t_us
            if self.last_us is None or t_us > self.last_us:
                self.last_us = t_us
        key = (0, name)
        self._counts[key] = self._counts.get(key, 0) + count

    # --- reading ---------------------------------------------------------------------------------------
    @property
    def span_s(self) -> float:
        if self.first_us is None or self.last_us is None:
            return 0.0
        return max(self.last_us - self.first_us, 0) * 1e-6

    def messages(self, sysid: int | None = None) -> list[MessageStats]:
        """Every message in the log (only ``sysid``'s if given), most frequent first."""
        by: dict[int | str, MessageStats] = {}
        for (sys_, key), n in self._counts.items():
            if sysid is not None and self.kind == "tlog" and sys_ != sysid:
                continue
            stats = by.get(key)
            if stats is None:
                if isinstance(key, str):
                    stats = MessageStats(key, None)
                else:
                    layout = layout_by_id(key)
                    stats = MessageStats(layout.name if layout is not None else f"#{key}", key)
                by[key] = stats
            stats.count += n
            if self.kind == "tlog":
                stats.sysids.add(sys_)
        return sorted(by.values(), key=lambda s: (-s.count, s.name))

    def names(self, sysid: int | None = None) -> set[str]:
        return {m.name for m in self.messages(sysid)}

    def sysids(self) -> dict[int, int]:
        """System id -> frames (tlogs only)."""
        out: dict[int, int] = {}
        if self.kind != "tlog":
            return out
        for (sys_, _key), n in self._counts.items():
            out[sys_] = out.get(sys_, 0) + n
        return dict(sorted(out.items()))

    def rate_hz(self, count: int) -> float | None:
        span = self.span_s
        return count / span if span > 0 else None

    @property
    def time_field(self) -> str:
        """The field every record's time is read from: what an instant message needs."""
        return {"tlog": "time_usec", "dataflash": "TimeUS"}.get(self.kind, "timestamp")

    def describe(self) -> str:
        """``220 MAVLink 1 and 20 MAVLink 2 frames over 39.0 s`` (a DataFlash or ULog log: its records), for errors."""
        if self.kind == "tlog":
            return f"{self.frames_v1} MAVLink 1 and {self.frames_v2} MAVLink 2 frames over {self.span_s:.1f} s"
        if self.kind == "ulog":
            return f"{self.records} ULog data messages over {self.span_s:.1f} s"
        return f"{self.records} DataFlash records over {self.span_s:.1f} s"

    def as_dict(self) -> dict[str, Any]:
        """The ``--json`` block: what the log holds."""
        return {
            "kind": self.kind,
            "records": self.records,
            "frames_v1": self.frames_v1,
            "frames_v2": self.frames_v2,
            "first_us": self.first_us,
            "last_us": self.last_us,
            "span_s": round(self.span_s, 6),
            "sysids": {str(s): n for s, n in self.sysids().items()},
            **({"dropouts": self.dropouts} if self.kind == "ulog" else {}),
            "messages": [
                {
                    "name": m.name,
                    "id": m.msgid,
                    "count": m.count,
                    "hz": None if (hz := self.rate_hz(m.count)) is None else round(hz, 3),
                    **({"sysids": sorted(m.sysids)} if self.kind == "tlog" else {}),
                }
                for m in self.messages()
            ],
        }

    def _with_rate(self, m: MessageStats) -> str:
        hz = self.rate_hz(m.count)
        return f"{m.name} {hz:.3g} Hz" if hz is not None else f"{m.name} x{m.count}"

    def lines(self) -> list[str]:
        """A few lines for people: what the log is, its system ids, its messages with their rates."""
        if self.kind == "tlog":
            what = (
                f"{self.frames_v1 + self.frames_v2} frames (MAVLink 1: {self.frames_v1}, MAVLink 2: {self.frames_v2})"
            )
            out = [f"{self.records} records over {self.span_s:.1f} s, {what}"]
        elif self.kind == "ulog":
            topics = {str(key).partition("[")[0] for _s, key in self._counts}
            out = [
                f"{self.records} ULog data messages over {self.span_s:.1f} s of timestamp, {len(topics)} topics in "
                f"{len(self._counts)} instances, {self.dropouts} dropouts"
            ]
        else:
            out = [f"{self.records} DataFlash records over {self.span_s:.1f} s of TimeUS, {len(self._counts)} messages"]
        ids = self.sysids()
        if ids:
            out.append("system ids " + ", ".join(f"{s} ({n} frames)" for s, n in ids.items()))
        msgs = self.messages()
        if msgs:
            shown = ", ".join(self._with_rate(m) for m in msgs[:_LIST_MESSAGES])
            more = f" (+{len(msgs) - _LIST_MESSAGES} more)" if len(msgs) > _LIST_MESSAGES else ""
            out.append(f"{'topics' if self.kind == 'ulog' else 'messages'} {shown}{more}")
        return out

    def providers(self, kinds: Iterable[str], sysid: int | None = None) -> list[str]:
        """``"attitude: ATTITUDE 10 Hz, AHRS2 4 Hz"`` for each kind of signal (``none`` when no message has it)."""
        msgs = {m.name: m for m in self.messages(sysid)}
        out = []
        for kind in dict.fromkeys(kinds):
            have = [self._with_rate(msgs[n]) for n in SIGNAL_KINDS.get(kind, ()) if n in msgs]
            out.append(f"{kind}: {', '.join(have) or 'none'}")
        return out

    def instant_candidates(self, sysid: int | None = None) -> list[str]:
        """Messages of the log that could define the sampling instant (a ``time_usec`` field; DataFlash: all)."""
        out = []
        for m in self.messages(sysid):
            if self.kind != "tlog":
                if m.name in self._timed and m.name not in ("FMT", "FMTU", "UNIT", "MULT", "PARM", "MSG"):
                    out.append(m.name)
                continue
            layout = layout_by_name(m.name)
            if layout is not None and "time_usec" in layout.offsets:
                out.append(m.name)
        return out


def field_ref(signal) -> str:
    """``MESSAGE.field`` or ``MESSAGE.field[index]`` (an array field), as a signal map writes it; a derived signal:
    ``angle_of_attack(velocity_ned, attitude_quaternion)``."""
    if signal.derivation is not None:
        return signal.derivation.describe()
    layout = layout_by_name(signal.message)
    array = signal.index or (layout is not None and layout.lengths.get(signal.field, 1) > 1)
    return f"{signal.message}.{signal.field}" + (f"[{signal.index}]" if array else "")


def _kinds_of(signal_name: str, message: str) -> tuple[str, ...]:
    """What a signal is: by its name when it is one of the plant's usual ones (alpha, q, theta...), else by the
    kinds its message carries."""
    return _KIND_BY_SIGNAL_NAME.get(signal_name.lower()) or tuple(
        kind for kind, names in SIGNAL_KINDS.items() if message in names
    )


def explain_missing(inventory: LogInventory, smap, names: Sequence[str], sysid: int | None = None) -> str | None:
    """Which signals of ``names`` (and the instant) the log has no message for, and which of its messages could
    carry them, in one line; None when every message the signal map reads is in the log (for ``sysid``)."""
    present = inventory.names(sysid)
    absent = [n for n in names if any(m not in present for m in smap.messages_of(n))]
    instant_absent = smap.instant not in present and not any(smap.instant in smap.messages_of(n) for n in absent)
    if not absent and not instant_absent:
        return None
    parts = []
    if instant_absent:
        parts.append(f"the instant ({smap.instant})")
    parts += [f"{n} ({field_ref(smap.measured[n])})" for n in absent]
    lacking = {m for n in absent for m in smap.messages_of(n) if m not in present}
    messages = sorted(lacking | ({smap.instant} if instant_absent else set()))
    where = f" from sysid {sysid}" if sysid is not None and inventory.kind == "tlog" else ""
    line = f"missing signals: {', '.join(parts)}: the log has no {' or '.join(messages)}{where}"
    kinds = [k for n in absent for k in _kinds_of(n, smap.measured[n].message)]
    hints = inventory.providers(kinds, sysid) if kinds else []
    if instant_absent or any(smap.instant in smap.messages_of(n) for n in absent):
        candidates = inventory.instant_candidates(sysid)
        hints.append(f"the instant ({inventory.time_field}): " + (", ".join(candidates[:8]) or "none"))
    if hints:
        line += "; what the log has instead: " + "; ".join(hints)
    ids = inventory.sysids()
    if sysid is not None and ids and sysid not in ids:
        line += f"; the log's system ids are {', '.join(map(str, ids))}"
    return line


def why_no_samples(inventory: LogInventory, smap, names: Sequence[str], sysid: int | None, h: float) -> str:
    """One line on why no sample could be assembled: the missing signals and where the log has such signals,
    or, when every message is there, that their time stamps never met at one sampling instant."""
    missing = explain_missing(inventory, smap, names, sysid)
    if missing is not None:
        return missing
    messages = ", ".join(dict.fromkeys([smap.instant, *(m for n in names for m in smap.messages_of(n))]))
    line = (
        f"every message the signal map reads is in the log ({messages}), but they never made one sample at "
        f"h = {h:g} s: their time stamps must fall within h/2 of the instant message's (the log's own "
        "sample spacing is a good h)"
    )
    slower = _slower_than_instant(inventory, smap, names, sysid)
    if slower:
        instant = inventory._with_rate(_stats(inventory, smap.instant, sysid))
        line += (
            f"; {', '.join(slower)} slower than the instant ({instant}): give the signals of the slower ones a "
            "'hold' of a little more than their period (latest values; the actuator's cannot), or take the instant "
            "from the actuator's message"
        )
    return line


def _stats(inventory: LogInventory, name: str, sysid: int | None) -> MessageStats:
    return next((m for m in inventory.messages(sysid) if m.name == name), MessageStats(name, None))


def _slower_than_instant(inventory: LogInventory, smap, names: Sequence[str], sysid: int | None) -> list[str]:
    """The timed messages the samples need that the log holds markedly fewer of than the instant's (with rates)."""
    instant = _stats(inventory, smap.instant, sysid).count
    timed = dict.fromkeys(
        smap.raw[n].message for n in smap.read_from(names) if smap.raw[n].timed and smap.raw[n].message != smap.instant
    )
    return [
        inventory._with_rate(stats)
        for stats in (_stats(inventory, m, sysid) for m in timed)
        if 0 < stats.count < 0.9 * instant
    ]


def read_inventory(path: str | Path) -> LogInventory:
    """The inventory of a tlog on its own (one pass; ``analyse`` and ``identify`` fill it while they read)."""
    from monitor.link.frames import FrameCounters, FrameParser
    from monitor.link.tlog import read_tlog

    counters = FrameCounters()
    parser = FrameParser(counters)
    inv = LogInventory()
    for t_us, frame in read_tlog(path):
        v1 = counters.frames_v1
        frames = parser.feed(frame)
        inv.add_frames(t_us, frames, counters.frames_v1 - v1)
    return inv
