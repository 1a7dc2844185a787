"""Fleet and model files: which plant, gains and signal map serve a system id.

A model is a plant, its gains (cross-checked against the plant's hash), its signal map and the estimator
built from them. An envelope plant (``form = "envelope"``, docs/explanation/envelope.md) with its envelope gains
file is one model too: a single-point model per point (its plant, its ``[point.<name>]`` gains, its own signal
map, which differs from the others' only in the operating point) and the schedule the vehicle table picks the
point with (``monitor.model.scheduling``); the model's own plant, gains and signal map are its first point's,
which is what the assembler and everything that does not schedule reads.

The fleet config is TOML, one ``[vehicle.<sysid>]`` table each with ``plant``, ``gains`` and optionally
``signals`` (an envelope plant with its envelope gains, and no ``signals``, serves a vehicle as well); a system
id it does not list gets the default ``--plant``/``--gains`` model, if any. ``load_model`` loads one model,
``load_fleet`` a fleet file of them; the vehicle table (``monitor.service.vehicles``) serves what they load.
"""

from __future__ import annotations

import logging
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import UserError
from monitor.gains import EnvelopeGainsFile, GainsFile, is_envelope_gains, read_envelope_gains, read_gains
from monitor.link.signals import MAVLINK, Layouts, SignalMap, signals_for_plant
from monitor.model.envelope import Envelope, is_envelope, load_envelope
from monitor.model.estimator import Estimator
from monitor.model.plant import Plant, load_plant
from monitor.model.scheduling import Schedule, schedule_of, state_offset

__all__ = ["VehicleModel", "EnvelopeModel", "Fleet", "load_model", "load_fleet"]

log = logging.getLogger("monitor.service.vehicles")  # the --force warning's logger name predates the split


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """A plant, its gains, its signal map and the estimator built from them (shared between vehicles)."""

    plant: Plant
    gains: GainsFile
    estimator: Estimator
    signals: SignalMap
    envelope: EnvelopeModel | None = None  # an envelope plant: its points (this model's fields are the first's)

    @property
    def h(self) -> float:
        return self.plant.h

    @property
    def name(self) -> str:
        """The plant's name, or the envelope's."""
        return self.envelope.envelope.name if self.envelope is not None else self.plant.name

    @property
    def digest(self) -> str:
        return self.envelope.envelope.digest if self.envelope is not None else self.plant.digest

    def point_models(self) -> tuple[VehicleModel, ...]:
        """Every single-point model this one runs: itself, or each point of its envelope."""
        return self.envelope.points if self.envelope is not None else (self,)


@dataclass(frozen=True, eq=False)
class EnvelopeModel:
    """An envelope's points as single-point models, the schedule that picks among them, and each point's trim: its
    offset in the estimator's state and its output and actuator trims (``monitor.model.scheduling``: the state is
    re-based every sample to the trims interpolated at the sample)."""

    envelope: Envelope
    gains: EnvelopeGainsFile
    points: tuple[VehicleModel, ...]
    schedule: Schedule
    # one row per point: what the trims interpolated between the points are weighted sums of (``trim_weights``)
    offset_rows: np.ndarray
    y0_rows: np.ndarray
    u0_rows: np.ndarray
    # each linear known input's trim (the points' [signals] condition), one value per point: interpolated too
    input_trim_rows: dict[str, np.ndarray]
    # ... and its column (state units per signal unit), one row per point: interpolated with the same weights,
    # because the throttle's pitching moment changes fast with the speed (on c172p its sign flips between 65 and
    # 100 kt, as the trimmed elevator it is felt through crosses zero): the nearest point's column alone was off
    # by its whole change between two points in a slow-down
    input_column_rows: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return self.envelope.names

    def unit(self, name: str) -> str:
        """The unit of schedule variable ``name``: its signal's, or a flight-condition quantity's (none)."""
        measured = self.points[0].signals.measured
        return measured[name].unit if name in measured else ""

    def describe(self) -> str:
        """``envelope c172p scheduled by airspeed: slow (airspeed 36 m/s), cruise (airspeed 51.4 m/s)``."""
        units = {n: self.unit(n) for n in self.envelope.schedule}
        places = ", ".join(
            f"{p.name} ("
            + ", ".join(f"{n} {p.at[n]:.6g}" + (f" {units[n]}" if units[n] else "") for n in self.envelope.schedule)
            + ")"
            for p in self.envelope.points
        )
        return f"envelope {self.envelope.name} scheduled by {', '.join(self.envelope.schedule)}: {places}"


def load_model(
    plant_spec: str | Path,
    gains_path: str | Path,
    force: bool = False,
    signals_file: str | Path | None = None,
    layouts: Layouts = MAVLINK,
) -> VehicleModel:
    """Load and cross-check a plant and its gains; a plant-hash mismatch is a UserError unless ``force``.

    ``layouts``: where the signal map's message names are looked up (a DataFlash log's own, for ``analyse``).
    An envelope plant file takes its envelope gains file (:func:`load_envelope_model`)."""
    if is_envelope(plant_spec):
        if signals_file is not None:
            raise UserError(
                f"--signals does not apply to the envelope plant {plant_spec}: each point's [signals] table is its "
                "signal map (its operating point is the point's own)"
            )
        return load_envelope_model(plant_spec, gains_path, force, layouts)
    if is_envelope_gains(gains_path):
        raise UserError(
            f"{gains_path}: is an envelope gains file (per-point gains, from `fault-monitor design --plant "
            f"ENVELOPE.toml`); it runs with its envelope plant file as --plant, not with {plant_spec}"
        )
    plant = load_plant(plant_spec)
    gains = read_gains(gains_path)
    gains.check_plant(plant)
    _check_hash(gains, plant, f"{gains_path}", str(plant_spec), force)
    return _single(plant, gains, signals_for_plant(plant, signals_file, layouts))


def _check_hash(gains: GainsFile, plant: Plant, label: str, plant_label: str, force: bool) -> None:
    designed_for = gains.meta.get("plant_hash")
    if designed_for != plant.digest:
        recorded = designed_for or "(no hash recorded)"
        what = f"{label}: designed for plant {recorded}, not for {plant_label} ({plant.digest})"
        if not force:
            raise UserError(f"{what}; use --force to run it anyway")
        log.warning("%s; running anyway (--force)", what)


def _single(plant: Plant, gains: GainsFile, signals: SignalMap) -> VehicleModel:
    limit = plant.actuator.limit
    if limit is not None:
        for name, u0 in zip(signals.actuator, signals.u0, strict=True):
            if not abs(u0) < limit:
                raise UserError(
                    f"{signals.source}: [signals] operating_point: '{name}' = {u0:g} is not inside the "
                    f"actuator limit +-{limit:g} of plant {plant.name}"
                )
    known = plant.known_inputs
    missing = [n for n in known.names if n not in signals.measured] if known is not None else []
    if missing:
        raise UserError(
            f"{signals.source}: [signals.measured] has no '{missing[0]}', which plant {plant.name}'s [known_inputs] "
            f"terms read ({', '.join(known.names) if known is not None else ''})"
        )
    return VehicleModel(
        plant,
        gains,
        Estimator(plant, gains.gains, u0=signals.u0, fault_time_constant=gains.fault_time_constant),
        signals,
    )


def _same_map(a: SignalMap, b: SignalMap) -> bool:
    """Two signal maps that read the same wire (their operating points may differ)."""
    keys = ("instant", "measured", "outputs", "actuator", "record", "command", "time_fields")
    return all(getattr(a, k) == getattr(b, k) for k in keys)


def load_envelope_model(
    plant_path: str | Path, gains_path: str | Path, force: bool = False, layouts: Layouts = MAVLINK
) -> VehicleModel:
    """An envelope plant and its envelope gains as one scheduled model (module docstring).

    Refused with one line: a single-point gains file, gains for other points or shapes, a hash mismatch (the
    envelope's or a point's, unless ``force``), points whose signal maps read different fields."""
    envelope = load_envelope(plant_path)
    gains = read_envelope_gains(gains_path)
    other = gains.check_envelope(envelope)
    if other is not None:
        if not force:
            raise UserError(f"{gains_path}: {other}; use --force to run it anyway")
        log.warning("%s: %s; running anyway (--force)", gains_path, other)
    points: list[VehicleModel] = []
    for point in envelope.points:
        gf = gains.points[point.name]
        _check_hash(gf, point.plant, f"{gains_path} [point.{point.name}]", f"point '{point.name}'", force)
        where = f"{plant_path}, point '{point.name}'"
        try:
            signals = signals_for_plant(point.plant, None, layouts)
        except UserError as exc:
            raise UserError(f"{where}: {exc}") from None
        if points and not _same_map(points[0].signals, signals):
            raise UserError(
                f"{where}: its [signals] reads other fields than point '{envelope.points[0].name}' (the points of an "
                "envelope must read the same MAVLink fields; only their operating points differ)"
            )
        points.append(_single(point.plant, gf, signals))
    offsets = [
        state_offset(
            m.plant.physical.C,
            m.signals.y0,
            m.signals.u0,
            m.plant.n,
            m.plant.q,
            m.plant.lags.last if m.plant.lags is not None else 0,
        )
        for m in points
    ]
    scheduled = EnvelopeModel(
        envelope,
        gains,
        tuple(points),
        schedule_of(envelope),
        np.array(offsets),
        np.array([m.signals.y0 for m in points], dtype=float),
        np.array([m.signals.u0 for m in points], dtype=float),
        _input_trims(envelope.name, points),
        {
            name: np.array([m.plant.known_inputs.linear[name] for m in points if m.plant.known_inputs is not None])
            for name in (points[0].plant.known_inputs.linear if points[0].plant.known_inputs is not None else {})
        },
    )
    first = points[0]
    return VehicleModel(first.plant, first.gains, first.estimator, first.signals, scheduled)


def _input_trims(name: str, points: list[VehicleModel]) -> dict[str, np.ndarray]:
    """The linear known inputs' trims per point; the points must share those inputs (one line otherwise)."""
    known = [m.plant.known_inputs for m in points]
    names = [tuple(k.linear) if k is not None else () for k in known]
    if any(n != names[0] for n in names):
        raise UserError(
            f"envelope '{name}': its points' [known_inputs.linear] name different signals ({names[0]} and "
            f"{next(n for n in names if n != names[0])}); identify every leg with the same --known-input"
        )
    return {s: np.array([k.trim[s] for k in known if k is not None]) for s in names[0]}


class Fleet:
    """sysid -> model, with an optional default for ids the fleet file does not list."""

    def __init__(self, default: VehicleModel | None, by_sysid: dict[int, VehicleModel] | None = None) -> None:
        self.default = default
        self.by_sysid = by_sysid or {}

    def model_for(self, sysid: int) -> VehicleModel | None:
        return self.by_sysid.get(sysid, self.default)

    def models(self) -> list[VehicleModel]:
        """Each model once (vehicles naming the same plant, gains and signals share one), default first."""
        distinct = {id(m): m for m in (self.default, *self.by_sysid.values()) if m is not None}
        return list(distinct.values())


def load_fleet(path: str | Path, default: VehicleModel | None, force: bool = False) -> Fleet:
    """Parse a fleet file::

        [vehicle.1]
        plant = "paper-continuous"
        gains = "gains/certified.toml"   # relative paths are relative to the fleet file
        signals = "signals/roll.toml"    # optional: a [signals] table for this vehicle

    Models are shared between vehicles that name the same plant, gains and signals.
    """
    path = Path(path)
    try:
        raw: dict[str, Any] = tomllib.loads(path.read_text("utf-8"))
    except FileNotFoundError:
        raise UserError(f"{path}: fleet file not found") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"{path}: cannot read fleet file: {exc}") from None
    unknown = sorted(set(raw) - {"vehicle"})
    if unknown:
        raise UserError(f"{path}: unknown table '{unknown[0]}' (expected [vehicle.<sysid>] tables)")
    vehicles = raw.get("vehicle") or {}
    if not isinstance(vehicles, dict):
        raise UserError(f"{path}: 'vehicle' must be tables [vehicle.<sysid>], not a value")
    models: dict[tuple[str, str, str | None], VehicleModel] = {}
    by_sysid: dict[int, VehicleModel] = {}
    for name, entry in vehicles.items():
        where = f"{path}: [vehicle.{name}]"
        if not name.isdigit() or not 1 <= int(name) <= 255:
            raise UserError(f"{where}: the table name must be a MAVLink system id 1-255")
        if not isinstance(entry, dict) or not {"plant", "gains"} <= set(entry) <= {"plant", "gains", "signals"}:
            raise UserError(f"{where}: needs the keys 'plant' and 'gains' (and optionally 'signals')")
        if not all(isinstance(v, str) for v in entry.values()):
            raise UserError(f"{where}: 'plant', 'gains' and 'signals' must be strings (a preset or a path)")
        plant_spec = entry["plant"]
        if plant_spec.endswith(".toml"):
            plant_spec = str(path.parent / plant_spec)
        gains_path = str(path.parent / entry["gains"])
        signals = str(path.parent / entry["signals"]) if "signals" in entry else None
        cache_key = (plant_spec, gains_path, signals)
        if cache_key not in models:
            models[cache_key] = load_model(plant_spec, gains_path, force, signals)
        by_sysid[int(name)] = models[cache_key]
    return Fleet(default, by_sysid)
