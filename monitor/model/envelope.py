"""Envelope plant files: one plant over several operating points, for a design certified over all of them.

A single-point plant is linear about one trim; a manoeuvre (a turn, a slow-down to approach speed) moves the trim,
and an estimator that keeps the old one reads the change as a fault. An envelope file holds the plant at several
operating points, each placed in a *schedule* of measured signals (airspeed, and optionally a second variable such
as bank angle or load factor):

.. code-block:: toml

    form = "envelope"
    name = "c172p"
    schedule = ["airspeed"]          # measured signals of the points' signal maps; one or two

    [[point]]
    name = "approach"
    at = { airspeed = 36.0 }         # the schedule's values at this point, in the signals' units
    [point.plant]                    # the point's complete single-point plant file, read by the same parser
    form = "continuous"
    ...
    [point.plant.signals]
    ...

Why strict, as single-point files are: each ``[point.plant]`` goes through :func:`plant_from_table`, so an unknown
key or a wrong shape there is the same one-line error it is in a plant file, naming the point. On top of it: the
points share ``h``, the delay interval, the dimensions of state, output, input, fault and disturbance, and the
names of the outputs and actuator signals (a scheduler switches among them on the same wire), while their
matrices, operating points and actuator limits may differ. Unknown keys, an ``at`` that names a variable outside
the schedule (or misses one), two points at the same place, fewer than two points: one line each.

Why the data is laid out for scheduling (``run``/``analyse`` will read it): each point carries its ``at`` in the
schedule's order (:attr:`Envelope.at_matrix`) and :meth:`Envelope.nearest` picks the point a measured value
schedules, which is *switching* among the points, what the envelope's certificate covers.

``is_envelope(path)`` tells an envelope file from a single-point one; ``load_plant`` refuses an envelope with a
line that says so, so its users keep working with single-point files unchanged.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import UserError
from monitor.model.flight_condition import DERIVED, needed_signals
from monitor.model.plant import Plant, plant_from_table
from monitor.model.plant_toml import _key, _value

__all__ = [
    "Envelope",
    "EnvelopePoint",
    "MAX_SCHEDULE",
    "is_envelope",
    "load_envelope",
    "envelope_with_air",
    "parse_envelope",
    "envelope_from_table",
    "envelope_toml",
    "assemble_envelope",
    "point_name",
]

MAX_SCHEDULE = 2  # scheduling variables: airspeed, and one more (bank angle, load factor)
_TOP_KEYS = {"form", "name", "description", "schedule", "point"}
_POINT_KEYS = {"name", "at", "plant"}
_NAME = re.compile(r"[A-Za-z0-9_-]+")  # a point's name is a bare TOML key: [point.<name>] in the gains file


@dataclass(frozen=True, eq=False)
class EnvelopePoint:
    """One operating point: its name, where it sits in the schedule (``at``, keyed by the schedule's names), and
    its complete single-point plant (matrices, operating point in ``plant.signals``, actuator limits)."""

    name: str
    at: dict[str, float]
    plant: Plant

    def at_values(self, schedule: Sequence[str]) -> tuple[float, ...]:
        return tuple(self.at[s] for s in schedule)


@dataclass(frozen=True, eq=False)
class Envelope:
    """A validated envelope: points in the file's order (``fault-monitor envelope`` writes them sorted by the
    schedule), all with the same ``h``, delay interval, dimensions and signal names."""

    name: str
    schedule: tuple[str, ...]
    points: tuple[EnvelopePoint, ...]
    description: str = ""
    source: str = "<memory>"
    digest: str = ""

    @property
    def first(self) -> Plant:
        return self.points[0].plant

    @property
    def h(self) -> float:
        return self.first.h

    @property
    def tau_min(self) -> float:
        return self.first.tau_min

    @property
    def tau_max(self) -> float:
        return self.first.tau_max

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.points)

    @property
    def at_matrix(self) -> np.ndarray:
        """``(points, schedule)``: each point's place, in the schedule's order (a scheduler's lookup table)."""
        return np.array([p.at_values(self.schedule) for p in self.points], dtype=float)

    def point(self, name: str) -> EnvelopePoint:
        for p in self.points:
            if p.name == name:
                return p
        raise KeyError(name)

    def nearest(self, values: Mapping[str, float]) -> EnvelopePoint:
        """The point closest to the measured schedule values, each variable scaled by the points' spread of it.

        Switching to the nearest point is what the envelope's common certificate covers; interpolating between
        points is not (see docs/explanation/envelope.md).
        """
        missing = [s for s in self.schedule if s not in values]
        if missing:
            raise KeyError(f"schedule variable(s) {', '.join(missing)} not given")
        at = self.at_matrix
        span = np.ptp(at, axis=0)
        span[span == 0] = 1.0
        x = np.array([float(values[s]) for s in self.schedule])
        return self.points[int(np.argmin(np.sum(((at - x) / span) ** 2, axis=1)))]


def is_envelope(path: str | Path) -> bool:
    """True when ``path`` is a readable TOML file with ``form = "envelope"`` (a preset name or any other file:
    False, and the single-point loader reports what is wrong with it)."""
    p = Path(str(path))
    if not p.is_file():
        return False
    try:
        raw = tomllib.loads(p.read_text("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return raw.get("form") == "envelope"


def load_envelope(path: str | Path) -> Envelope:
    """Read and validate an envelope plant file; every problem is one line naming the file (and the point)."""
    p = Path(str(path))
    if not p.is_file():
        raise UserError(f"envelope plant file '{path}' is not a readable file")
    try:
        text = p.read_text("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read envelope plant file: {exc}") from None
    return parse_envelope(text, source=str(path))


def parse_envelope(text: str, source: str = "<memory>") -> Envelope:
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{source}: not valid TOML: {exc}") from None
    return envelope_from_table(raw, source)


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def envelope_from_table(raw: dict[str, Any], source: str) -> Envelope:
    """Validate a parsed envelope table (see the module docstring) and build the Envelope."""
    if raw.get("form") != "envelope":
        raise UserError(
            f"{source}: key 'form' must be \"envelope\" for an envelope plant file, got {raw.get('form')!r}"
        )
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise UserError(f"{source}: unknown key '{unknown[0]}' (allowed: {', '.join(sorted(_TOP_KEYS))})")
    schedule = _schedule(raw.get("schedule"), source)
    entries = raw.get("point")
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise UserError(f"{source}: needs [[point]] entries (each with name, at and a [point.plant] table)")
    if len(entries) < 2:
        raise UserError(f"{source}: an envelope needs at least 2 points, got {len(entries)}")
    points: list[EnvelopePoint] = []
    seen_at: dict[tuple[float, ...], str] = {}
    for i, entry in enumerate(entries):
        point = _point(entry, i, schedule, source)
        if any(p.name == point.name for p in points):
            raise UserError(f"{source}: two points are named '{point.name}' (each point needs its own name)")
        place = point.at_values(schedule)
        if place in seen_at:
            where = ", ".join(f"{s} = {v:g}" for s, v in zip(schedule, place, strict=True))
            raise UserError(
                f"{source}: points '{seen_at[place]}' and '{point.name}' are both at {where} "
                "(each point needs its own place in the schedule)"
            )
        seen_at[place] = point.name
        if points:
            _check_shared(points[0], point, source)
        points.append(point)
    name = raw.get("name", Path(source).stem)
    description = raw.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise UserError(f"{source}: key '{key}' must be a string, got {value!r}")
    return Envelope(
        name=str(name),
        schedule=schedule,
        points=tuple(points),
        description=str(description),
        source=source,
        digest=_digest(schedule, points),
    )


def _schedule(value: Any, source: str) -> tuple[str, ...]:
    if value is None:
        raise UserError(
            f"{source}: key 'schedule' is missing (the measured signals that schedule, e.g. [\"airspeed\"])"
        )
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise UserError(f"{source}: key 'schedule' must be a list of signal names, e.g. [\"airspeed\"], got {value!r}")
    if len(value) > MAX_SCHEDULE:
        raise UserError(f"{source}: key 'schedule' names {len(value)} variables; at most {MAX_SCHEDULE} can schedule")
    if len(set(value)) != len(value):
        raise UserError(f"{source}: key 'schedule' names a variable twice: {value}")
    return tuple(value)


def _point(entry: dict[str, Any], index: int, schedule: tuple[str, ...], source: str) -> EnvelopePoint:
    name = entry.get("name")
    label = f"[[point]] number {index + 1}"
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise UserError(
            f"{source}: {label}: key 'name' must be a name of letters, digits, '-' and '_' (it becomes a table "
            f"name in the gains file), got {name!r}"
        )
    where = f"{source}: point '{name}'"
    unknown = sorted(set(entry) - _POINT_KEYS)
    if unknown:
        raise UserError(f"{where}: unknown key '{unknown[0]}' (allowed: {', '.join(sorted(_POINT_KEYS))})")
    at = entry.get("at")
    if not isinstance(at, dict):
        raise UserError(
            f"{where}: key 'at' must be a table of the schedule's values, e.g. at = {{ {schedule[0]} = 51.4 }}"
        )
    for var in at:
        if var not in schedule:
            raise UserError(f"{where}: 'at' names '{var}', which is not in the schedule ({', '.join(schedule)})")
    missing = [s for s in schedule if s not in at]
    if missing:
        raise UserError(f"{where}: 'at' misses the schedule variable(s) {', '.join(repr(m) for m in missing)}")
    for var, value in at.items():
        if not _finite(value):
            raise UserError(f"{where}: 'at.{var}' must be a finite number (the signal's units), got {value!r}")
    table = entry.get("plant")
    if not isinstance(table, dict):
        raise UserError(f"{where}: needs a [point.plant] table (the point's complete single-point plant file)")
    if table.get("form") == "envelope":
        raise UserError(f"{where}: [point.plant] must be a single-point plant (form continuous or discrete)")
    plant = plant_from_table(table, f"{source}, point '{name}'")
    if "name" not in table:
        plant = replace(plant, name=name)
    _check_signals(plant, where, schedule, {k: float(v) for k, v in at.items()})
    return EnvelopePoint(name=name, at={s: float(at[s]) for s in schedule}, plant=plant)


def _check_signals(plant: Plant, where: str, schedule: tuple[str, ...], at: dict[str, float]) -> None:
    """The schedule's signals must be measured by the point's signal map (its full check is the link layer's, at
    ``run``, as for any plant); a scheduling signal that is in the operating point must be scheduled at it."""
    signals = plant.signals
    if not isinstance(signals, dict):
        raise UserError(
            f"{where}: its plant has no [signals] table; an envelope's points need one whose [signals.measured] "
            f"names the schedule's signals ({', '.join(schedule)})"
        )
    measured = signals.get("measured")
    if not isinstance(measured, dict):
        raise UserError(f"{where}: [point.plant.signals] needs a [signals.measured] table")
    for var in schedule:
        for signal in needed_signals([var]):
            if signal not in measured:
                raise UserError(
                    f"{where}: schedule variable '{var}' "
                    + (f"reads '{signal}', which " if signal != var else "")
                    + f"is not a measured signal of its [signals] (measured: {', '.join(measured)})"
                )
    for key in ("outputs", "actuator"):
        names = signals.get(key)
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise UserError(f"{where}: [point.plant.signals] needs '{key}', a list of signal names")
    op = _trim_and_condition(signals)
    if op:
        for var in schedule:
            value = op.get(var)
            if (
                isinstance(value, (int, float))
                and _finite(value)
                and abs(value - at[var]) > 1e-6 * max(1.0, abs(at[var]))
            ):
                raise UserError(
                    f"{where}: at {var} = {at[var]:g} but its [signals] {_holder(signals, var)} has {var} = "
                    f"{value:g} (a scheduling signal of the operating point is scheduled at its trim value)"
                )


def _trim_and_condition(signals: dict[str, Any]) -> dict[str, Any]:
    """A point's ``[signals] operating_point`` and ``condition`` in one table (their names never overlap), with
    the flight-condition quantities they give (``monitor.model.flight_condition``): where its schedule values come
    from (airspeed from the trim or the condition, bank and the bank's load factor from the condition)."""
    both: dict[str, Any] = {}
    for key in ("operating_point", "condition"):
        table = signals.get(key)
        if isinstance(table, dict):
            both.update(table)
    for name, derived in DERIVED.items():  # bank_load_factor from the condition's roll
        if all(isinstance(both.get(s), (int, float)) and _finite(both[s]) for s in derived.inputs):
            both[name] = derived.fn(both)
    return both


def _holder(signals: dict[str, Any], var: str) -> str:
    """Which of ``[signals]``' tables holds ``var``'s trim value."""
    return "operating_point" if var in (signals.get("operating_point") or {}) else "condition"


def _check_shared(first: EnvelopePoint, point: EnvelopePoint, source: str) -> None:
    a, b = first.plant, point.plant
    where = f"{source}: point '{point.name}'"
    for key in ("h", "tau_min", "tau_max"):
        if getattr(a, key) != getattr(b, key):
            raise UserError(
                f"{where}: {key} = {getattr(b, key):g} differs from point '{first.name}' ({getattr(a, key):g}); "
                "the points of an envelope share h and the delay interval"
            )
    for key, what in (("n", "states"), ("l", "outputs"), ("m", "inputs"), ("q", "faults"), ("p", "disturbances")):
        if getattr(a, key) != getattr(b, key):
            raise UserError(
                f"{where}: has {getattr(b, key)} {what}, point '{first.name}' {getattr(a, key)}; the points of an "
                "envelope share the dimensions of state, output, input, fault and disturbance"
            )
    for key in ("outputs", "actuator"):
        na = (a.signals or {}).get(key)
        nb = (b.signals or {}).get(key)
        if na != nb:
            raise UserError(
                f"{where}: [signals] {key} = {nb} differs from point '{first.name}' ({na}); the points of an "
                "envelope read the same signals"
            )


def _digest(schedule: tuple[str, ...], points: Sequence[EnvelopePoint]) -> str:
    """The envelope's hash: its schedule and each point's name, place and plant hash (the plants' own digests,
    so gains for an envelope stay valid when a point's [signals] or [identification] table is edited)."""
    content = {
        "schedule": list(schedule),
        "points": [{"name": p.name, "at": [p.at[s] for s in schedule], "plant": p.plant.digest} for p in points],
    }
    canonical = json.dumps(content, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(canonical.encode()).hexdigest()[:16]


# -- writing -----------------------------------------------------------------------------------------------------


def point_name(text: str) -> str:
    """A point name from a file stem or plant name: letters, digits, ``-`` and ``_`` (others become ``-``)."""
    name = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-")
    return name or "point"


_INLINE_TABLES = ("operating_point", "condition")  # flat tables of [signals] that identify writes inline


def _flat(value: Any) -> bool:
    return isinstance(value, dict) and not any(isinstance(v, (dict, list)) and _nested(v) for v in value.values())


def _nested(value: Any) -> bool:
    return isinstance(value, dict) or (isinstance(value, list) and any(isinstance(v, dict) for v in value))


def _table_lines(table: Mapping[str, Any], prefix: str, depth: int) -> list[str]:
    """``table`` as TOML under ``[prefix]``: plain keys first, then sub-tables, then arrays of tables.

    A flat table below the top (an operating point, a measured signal) is written inline, as ``identify`` writes
    it; the others become ``[prefix.key]`` tables. Every value reads back as the same Python value, so a point's
    plant hash in the envelope is that of its own file.
    """
    plain: list[str] = []
    subs: list[tuple[str, Mapping[str, Any]]] = []
    arrays: list[tuple[str, list[Mapping[str, Any]]]] = []
    all_dicts = bool(table) and all(isinstance(v, dict) for v in table.values())
    for key, value in table.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            arrays.append((key, value))
        elif isinstance(value, dict) and not (depth >= 1 and _flat(value) and (all_dicts or key in _INLINE_TABLES)):
            subs.append((key, value))
        else:
            try:
                plain.append(f"{_key(key)} = {_value(value)}")
            except TypeError as exc:
                raise UserError(f"{prefix}.{key}: {exc}") from None
    lines = plain
    for key, value in subs:
        lines += ["", f"[{prefix}.{_key(key)}]", *_table_lines(value, f"{prefix}.{_key(key)}", depth + 1)]
    for key, items in arrays:
        for item in items:
            lines += [f"[[{prefix}.{_key(key)}]]", *_table_lines(item, f"{prefix}.{_key(key)}", depth + 1)]
    return lines


def envelope_toml(
    name: str,
    schedule: Sequence[str],
    points: Sequence[tuple[str, Mapping[str, float], Mapping[str, Any]]],
    description: str = "",
    header: Sequence[str] = (),
) -> str:
    """The envelope file's text: ``points`` are ``(name, at, raw single-point plant table)`` in the order to write."""
    lines = [f"# {line}" for line in header]
    lines += ['form = "envelope"', f"name = {_value(name)}"]
    if description:
        lines.append(f"description = {_value(description)}")
    lines.append(f"schedule = {_value(list(schedule))}")
    for point, at, raw in points:
        lines += ["", "[[point]]", f"name = {_value(point)}", f"at = {_value({s: float(at[s]) for s in schedule})}"]
        lines += ["[point.plant]", *_table_lines(raw, "point.plant", 0)]
    return "\n".join(lines) + "\n"


def envelope_with_air(
    envelope: Envelope,
    gust: Mapping[str, float],
    measured_at: float | None,
    turbulence: str | None,
    source: str,
) -> str:
    """The envelope file's text with a ``[disturbance]`` table in every point: the gust measured once (at airspeed
    ``measured_at``, m/s) carried to each point by its trim airspeed.

    Why scale by airspeed: ``d`` is the gust seen as an angle of attack, ``w_g / V``, and its time scale is the
    gust's length over the speed, ``L / V`` (the Dryden form the plant's Gauss-Markov ``d`` stands for), so one
    air met at ``V_m`` is ``sigma V_m / V`` and ``time_constant V_m / V`` at a point flown at ``V``. A point whose
    trim has no airspeed (or a ``measured_at`` of None) gets the gust as measured."""
    points = []
    for point in envelope.points:
        plant = point.plant
        if plant.raw is None:
            raise UserError(f"{envelope.source}, point '{point.name}': not read from a file (no table to copy)")
        speed = _trim_and_condition(plant.signals or {}).get("airspeed")
        scaled = isinstance(speed, (int, float)) and _finite(speed) and speed > 0 and measured_at is not None
        ratio = float(measured_at) / float(speed) if scaled else 1.0  # type: ignore[arg-type]
        table: dict[str, Any] = {
            "sigma": float(f"{gust['sigma'] * ratio:.6g}"),
            "time_constant": float(f"{gust['time_constant'] * ratio:.6g}"),
        }
        if turbulence is not None:
            table["turbulence"] = turbulence
        table["source"] = source + (f"; scaled from {measured_at:.4g} to {speed:.4g} m/s" if scaled else "")
        raw = {key: value for key, value in plant.raw.items() if key != "disturbance"}
        raw["disturbance"] = table
        points.append((point.name, point.at, raw))
    header = [f"{envelope.name}: the air of {source}, measured by fault-monitor identify --air-only."]
    text = envelope_toml(envelope.name, envelope.schedule, points, envelope.description, header)
    parse_envelope(text, source=envelope.source)
    return text


def assemble_envelope(
    plants: Sequence[tuple[str, Plant]], schedule: Sequence[str], name: str, description: str = ""
) -> str:
    """An envelope file from single-point plants (``(point name, plant)``, each what ``identify`` writes from one
    leg): each point's ``at`` is its operating point's value of the schedule's signals; the points are sorted by
    the schedule. The text is validated by :func:`parse_envelope` before it is returned."""
    sched = _schedule(list(schedule), "--schedule")
    rows: list[tuple[tuple[float, ...], str, dict[str, float], dict[str, Any]]] = []
    for point, plant in plants:
        if plant.raw is None:
            raise UserError(f"{plant.source}: not read from a plant file (no table to copy into the envelope)")
        op = _trim_and_condition(plant.signals or {})
        if not op:
            raise UserError(
                f"{plant.source}: has no [signals] operating_point; the schedule's signals ({', '.join(sched)}) must "
                "be in every point's operating point or flight condition"
            )
        at: dict[str, float] = {}
        for var in sched:
            value = op.get(var)
            if not isinstance(value, (int, float)) or not _finite(value):
                needs = DERIVED[var].inputs if var in DERIVED else (var,)
                raise UserError(
                    f"{plant.source}: [signals] operating_point and condition have no {var!r} (they have "
                    f"{', '.join(op)}); the schedule's signals must be in every point's operating point or condition "
                    f"(identify writes {', '.join(needs)} into the condition when its signal map measures "
                    f"{'them' if len(needs) > 1 else 'it'}: identify the leg again)"
                )
            at[var] = float(value)
        rows.append((tuple(at[s] for s in sched), point, at, plant.raw))
    rows.sort(key=lambda r: r[0])
    header = [
        f"Assembled by fault-monitor envelope from {len(rows)} single-point plants, scheduled by {', '.join(sched)}."
    ]
    text = envelope_toml(name, sched, [(p, at, raw) for _, p, at, raw in rows], description, header)
    parse_envelope(text, source=f"envelope '{name}'")
    return text
