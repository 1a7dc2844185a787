"""A mission: the TOML timeline of segments a JSBSim aircraft flies on its own autopilot (``--mission FILE``).

A file is a list of ``[[segment]]`` tables, flown one after the other::

    [[segment]]
    name = "level"          # its name, unique in the file (the truth stream's ``segment``)
    duration = 60           # seconds
    airspeed = 100          # knots, calibrated
    altitude = 3000         # feet above sea level ... or climb = 500 (ft/min; negative: a descent)
    bank = 0                # degrees, right positive ... or heading = 90 (degrees, true)
    excite = "prbs:1:30"    # optional: a PRBS on the autopilot's elevator, as --excite takes it

Each segment has exactly one of ``altitude`` and ``climb`` and exactly one of ``bank`` and ``heading``. The
aircraft is trimmed at the first segment's airspeed and altitude, so the first segment must give an altitude.
Commands change smoothly between segments: the autopilot's references are rate-limited (airspeed 1 kt/s,
altitude 500 ft/min, bank 10 deg/s; ``sim_vehicle.autopilot``). A PRBS leg starts with its segment, holds each
level one sample (``Excitation``'s sequence, seeded by the run's seed plus the segment's index) and must end
within the segment.

Why strict: a mission is an experiment written down; a key mistyped (``bnak``) or a value of the wrong type
silently ignored would fly another one. Every error is one line naming the file, the segment and the key.

>>> m = parse_mission({"segment": [{"name": "a", "duration": 10, "airspeed": 90, "altitude": 2000, "bank": 0},
...     {"name": "b", "duration": 5, "airspeed": 90, "climb": 500, "heading": 90}]}, "m.toml")
>>> [s.name for s in m.segments], m.duration, m.segments[1].start
(['a', 'b'], 15.0, 10.0)
>>> parse_mission({"segment": [{"name": "a", "duration": 10, "airspeed": 90, "altitude": 2000}]}, "m.toml")
Traceback (most recent call last):
monitor.errors.UserError: --mission m.toml: segment 1 ('a'): needs exactly one of 'bank' and 'heading'
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.wire.specs import Excitation, parse_excite_spec
from sim_vehicle.autopilot import Targets

__all__ = ["Segment", "Mission", "Timeline", "load_mission", "parse_mission", "MAX_BANK_DEG", "SEGMENT_KEYS"]

SEGMENT_KEYS = ("name", "duration", "airspeed", "altitude", "climb", "bank", "heading", "excite", "excite_throttle")
THROTTLE_SEED = 0x7A  # the throttle's PRBS is seeded apart from the elevator's: two independent inputs
# ... and dwells 2-6 s between switches, not the elevator's 0.2-0.8 s: an engine and its propeller answer a throttle
# step in a second or more (c172p: a 0.2-0.8 s PRBS of +-8 % moved the identified pitching moment by nothing
# measurable, where the slow-down's throttle moves the elevator's trim by about 0.03 deg per percent)
THROTTLE_DWELL_S = (2.0, 6.0)
MAX_BANK_DEG = 75.0  # n = 3.9 g in a level turn: beyond a light aircraft's limit load (3.8 g)


@dataclass(frozen=True)
class Segment:
    """One leg of a mission: from ``start`` for ``duration`` seconds, fly these targets."""

    name: str
    start: float
    duration: float
    airspeed_kt: float
    altitude_ft: float | None = None
    climb_fpm: float | None = None
    bank_deg: float | None = None
    heading_deg: float | None = None
    excite: Excitation | None = None
    excite_throttle: Excitation | None = None  # a PRBS of +-AMP percent on the held throttle (needs ``excite``)

    @cached_property
    def targets(self) -> Targets:
        """What the autopilot is asked to fly (made once: it is read at every JSBSim step)."""
        return Targets(self.airspeed_kt, self.altitude_ft, self.climb_fpm, self.bank_deg, self.heading_deg)


@dataclass(frozen=True)
class Mission:
    """The segments of a mission file, in flying order (each one's ``start`` where the previous one ends)."""

    source: str
    segments: tuple[Segment, ...]

    @property
    def duration(self) -> float:
        last = self.segments[-1]
        return last.start + last.duration

    def steps(self, h: float) -> int:
        """Samples in the whole mission at period ``h`` (the run's length unless ``--steps`` is shorter)."""
        return max(1, int(math.ceil(self.duration / h - 1e-9)))

    def timeline(self, h: float, seed: int) -> Timeline:
        return Timeline(self, h, seed)

    def __str__(self) -> str:
        return f"{self.source} ({len(self.segments)} segments, {self.duration:g} s)"


def _levels(
    excitation: Excitation | None, h: float, seed: int, dwell: tuple[float, float] | None = None
) -> list[float]:
    if excitation is None:
        return []
    signs = excitation.signs(h, seed) if dwell is None else excitation.signs(h, seed, dwell)
    return [sign * excitation.amplitude for sign in signs]


class Timeline:
    """Which segment is flown at time t, and the PRBS levels it adds to the elevator and the throttle then (times
    never go back)."""

    def __init__(self, mission: Mission, h: float, seed: int) -> None:
        self.mission = mission
        self.h = h
        self.index = 0
        self._levels = [_levels(s.excite, h, seed + i) for i, s in enumerate(mission.segments)]
        self._throttle = [
            _levels(s.excite_throttle, h, seed + i + THROTTLE_SEED, THROTTLE_DWELL_S)
            for i, s in enumerate(mission.segments)
        ]

    def _i(self, t: float) -> tuple[Segment, int]:
        segments = self.mission.segments
        while self.index + 1 < len(segments) and t >= segments[self.index + 1].start - 1e-9:
            self.index += 1
        segment = segments[self.index]
        return segment, int(math.floor((t - segment.start) / self.h + 1e-9))

    def at(self, t: float) -> tuple[Segment, float]:
        """The segment flown at ``t`` (the last one after the mission's end) and its elevator excitation (deg)."""
        segment, i = self._i(t)
        levels = self._levels[self.index]
        return segment, levels[i] if 0 <= i < len(levels) else 0.0

    def throttle_at(self, t: float) -> float:
        """The throttle's excitation at ``t`` (percent; 0 outside a leg's ``excite_throttle``)."""
        _segment, i = self._i(t)
        levels = self._throttle[self.index]
        return levels[i] if 0 <= i < len(levels) else 0.0


def load_mission(path: str | Path) -> Mission:
    """The mission in the TOML file ``path`` (a one-line ``UserError`` naming what is wrong)."""
    try:
        raw = tomllib.loads(Path(path).read_text("utf-8"))
    except OSError as exc:
        raise UserError(f"--mission {path}: cannot read: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UserError(f"--mission {path}: not valid TOML: {exc}") from None
    return parse_mission(raw, str(path))


def parse_mission(raw: Mapping[str, Any], source: str) -> Mission:
    """A mission from a parsed TOML table (``source`` names it in errors)."""
    where = f"--mission {source}"
    unknown = [k for k in raw if k != "segment"]
    if unknown:
        raise UserError(f"{where}: unknown key '{unknown[0]}' (a mission file holds [[segment]] tables only)")
    tables = raw.get("segment")
    if not isinstance(tables, list) or not tables or not all(isinstance(t, dict) for t in tables):
        raise UserError(f"{where}: expected one or more [[segment]] tables")
    segments: list[Segment] = []
    start = 0.0
    for i, table in enumerate(tables, 1):
        segment = _segment(table, start, f"{where}: segment {i}", first=i == 1)
        if any(s.name == segment.name for s in segments):
            raise UserError(f"{where}: segment {i} ('{segment.name}'): key 'name': another segment has this name")
        segments.append(segment)
        start += segment.duration
    return Mission(source, tuple(segments))


def _segment(table: Mapping[str, Any], start: float, where: str, first: bool) -> Segment:
    name = table.get("name")
    if not isinstance(name, str) or not name.strip():
        got = "missing" if name is None else f"expected a non-empty string, got {name!r}"
        raise UserError(f"{where}: key 'name': {got}")
    where = f"{where} ('{name}')"
    for key in table:
        if key not in SEGMENT_KEYS:
            raise UserError(f"{where}: unknown key '{key}' (known: {', '.join(SEGMENT_KEYS)})")

    def number(key: str, check: Any = None, must: str = "") -> float | None:
        value = table.get(key)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise UserError(f"{where}: key '{key}': expected a number, got {value!r}")
        if check is not None and not check(float(value)):
            raise UserError(f"{where}: key '{key}': {must}, got {value:g}")
        return float(value)

    def required(key: str, value: float | None) -> float:
        if value is None:
            raise UserError(f"{where}: key '{key}': missing")
        return value

    duration = required("duration", number("duration", lambda v: v > 0, "must be positive (seconds)"))
    airspeed = required("airspeed", number("airspeed", lambda v: v > 0, "must be positive (knots, calibrated)"))
    altitude = number("altitude", lambda v: v > 0, "must be above the ground (feet above sea level, JSBSim's terrain)")
    climb = number("climb")
    bank = number("bank", lambda v: abs(v) <= MAX_BANK_DEG, f"must be within +-{MAX_BANK_DEG:g} deg")
    heading = number("heading", lambda v: 0 <= v <= 360, "must be in [0, 360] deg")
    if (altitude is None) == (climb is None):
        raise UserError(f"{where}: needs exactly one of 'altitude' (ft) and 'climb' (ft/min)")
    if (bank is None) == (heading is None):
        raise UserError(f"{where}: needs exactly one of 'bank' and 'heading'")
    if first and altitude is None:
        raise UserError(f"{where}: key 'altitude': missing (the aircraft is trimmed at the first segment's altitude)")
    excite = _prbs(table, "excite", where, duration, "prbs:1:30")
    if "excite_throttle" in table and excite is None:
        raise UserError(
            f"{where}: key 'excite_throttle' needs 'excite' (the throttle is excited in an identification leg, "
            "where it is held)"
        )
    excite_throttle = _prbs(table, "excite_throttle", where, duration, "prbs:5:30")
    if excite_throttle is not None and not excite_throttle.amplitude <= 50.0:
        raise UserError(f"{where}: key 'excite_throttle': the amplitude is in percent of throttle, at most 50")
    return Segment(name, start, duration, airspeed, altitude, climb, bank, heading, excite, excite_throttle)


def _prbs(table: Mapping[str, Any], key: str, where: str, duration: float, example: str) -> Excitation | None:
    """A segment's PRBS key (``excite``, ``excite_throttle``): None when absent or "none"; one line when wrong."""
    if key not in table:
        return None
    text = table[key]
    if not isinstance(text, str):
        raise UserError(f"{where}: key '{key}': expected a string such as \"{example}\", got {text!r}")
    try:
        excitation = parse_excite_spec(text)
    except UserError as exc:
        raise UserError(f"{where}: key '{key}': {exc}") from None
    if excitation is not None and excitation.seconds > duration + 1e-9:
        raise UserError(
            f"{where}: key '{key}': the PRBS lasts {excitation.seconds:g} s, longer than the segment ({duration:g} s)"
        )
    return excitation
