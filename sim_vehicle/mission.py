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

SEGMENT_KEYS = ("name", "duration", "airspeed", "altitude", "climb", "bank", "heading", "excite")
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


class Timeline:
    """Which segment is flown at time t, and the PRBS level it adds to the elevator then (times never go back)."""

    def __init__(self, mission: Mission, h: float, seed: int) -> None:
        self.mission = mission
        self.h = h
        self.index = 0
        self._levels = [
            [sign * s.excite.amplitude for sign in s.excite.signs(h, seed + i)] if s.excite is not None else []
            for i, s in enumerate(mission.segments)
        ]

    def at(self, t: float) -> tuple[Segment, float]:
        """The segment flown at ``t`` (the last one after the mission's end) and its excitation (deg)."""
        segments = self.mission.segments
        while self.index + 1 < len(segments) and t >= segments[self.index + 1].start - 1e-9:
            self.index += 1
        segment, levels = segments[self.index], self._levels[self.index]
        i = int(math.floor((t - segment.start) / self.h + 1e-9))
        return segment, levels[i] if 0 <= i < len(levels) else 0.0


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
    excite = None
    if "excite" in table:
        text = table["excite"]
        if not isinstance(text, str):
            raise UserError(f"{where}: key 'excite': expected a string such as \"prbs:1:30\", got {text!r}")
        try:
            excite = parse_excite_spec(text)
        except UserError as exc:
            raise UserError(f"{where}: key 'excite': {exc}") from None
        if excite is not None and excite.seconds > duration + 1e-9:
            raise UserError(
                f"{where}: key 'excite': the PRBS lasts {excite.seconds:g} s, longer than the segment ({duration:g} s)"
            )
    return Segment(name, start, duration, airspeed, altitude, climb, bank, heading, excite)
