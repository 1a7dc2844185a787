"""The per-vehicle table: which plant and gains serve a system id, and each vehicle's loop state.

A vehicle appears on its first sample (its estimator state starts at zero), and is forgotten after
``timeout`` seconds of silence. Its model comes from the fleet config (TOML, one ``[vehicle.<sysid>]``
table each with ``plant`` and ``gains``) or else from the default ``--plant``/``--gains``; a system id
with neither is refused with one log line (and counted), never a crash.

Why duplicates and stale samples are filtered here and not only in ``Estimator.step``: they must be
counted separately (a duplicated datagram and a late, reordered one are different network faults), and
neither may be processed twice. Why a "restart" rule: a vehicle process restarted under the same sysid
comes from a new UDP source address and starts again at k = 0, which would otherwise look stale until
the timeout; a new address whose sample goes backwards while the old address has been silent for
``restart_silence`` seconds starts a fresh state. A replayed old datagram from another address while
the vehicle is live does not qualify, so it is still refused as stale.
"""

from __future__ import annotations

import logging
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.estimator import Estimator, EstimatorState, StepResult
from monitor.gains import GainsFile, read_gains
from monitor.plant import Plant, load_plant
from monitor.service.alarm import Alarm, AlarmConfig
from monitor.service.delay import DelayTracker
from monitor.service.udp_endpoint import Telemetry

__all__ = ["VehicleModel", "Fleet", "load_model", "load_fleet", "Vehicle", "Processed", "TableCounters",
           "VehicleTable"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """A plant, its gains and the estimator built from them (shared by every vehicle that uses them)."""

    plant: Plant
    gains: GainsFile
    estimator: Estimator
    C_rows: tuple[tuple[float, float], ...]  # y = C [alpha; q] as Python floats: cheaper than numpy at 1x2

    @property
    def h(self) -> float:
        return self.plant.h


def load_model(plant_spec: str | Path, gains_path: str | Path, force: bool = False) -> VehicleModel:
    """Load and cross-check a plant and its gains; a plant-hash mismatch is a UserError unless ``force``."""
    plant = load_plant(plant_spec)
    gains = read_gains(gains_path)
    gains.check_plant(plant)
    designed_for = gains.meta.get("plant_hash")
    if designed_for != plant.digest:
        what = (f"{gains_path}: designed for plant {designed_for or '(no hash recorded)'}, "
                f"not for {plant_spec} ({plant.digest})")
        if not force:
            raise UserError(f"{what}; use --force to run it anyway")
        log.warning("%s; running anyway (--force)", what)
    if plant.C.shape[1] != 2:
        raise UserError(f"{plant_spec}: the MAVLink telemetry carries [alpha, q], so C must have 2 columns")
    C_rows = tuple((float(r[0]), float(r[1])) for r in plant.C)
    return VehicleModel(plant, gains, Estimator(plant, gains.gains), C_rows)


class Fleet:
    """sysid -> model, with an optional default for ids the fleet file does not list."""

    def __init__(self, default: VehicleModel | None, by_sysid: dict[int, VehicleModel] | None = None) -> None:
        self.default = default
        self.by_sysid = by_sysid or {}

    def model_for(self, sysid: int) -> VehicleModel | None:
        return self.by_sysid.get(sysid, self.default)


def load_fleet(path: str | Path, default: VehicleModel | None, force: bool = False) -> Fleet:
    """Parse a fleet file::

        [vehicle.1]
        plant = "paper-continuous"
        gains = "gains/certified.toml"   # relative paths are relative to the fleet file

    Models are shared between vehicles that name the same plant and gains.
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
    models: dict[tuple[str, str], VehicleModel] = {}
    by_sysid: dict[int, VehicleModel] = {}
    for name, entry in (raw.get("vehicle") or {}).items():
        where = f"{path}: [vehicle.{name}]"
        if not name.isdigit() or not 1 <= int(name) <= 255:
            raise UserError(f"{where}: the table name must be a MAVLink system id 1-255")
        if not isinstance(entry, dict) or set(entry) != {"plant", "gains"}:
            raise UserError(f"{where}: needs exactly the keys 'plant' and 'gains'")
        plant_spec = str(entry["plant"])
        if plant_spec.endswith(".toml"):
            plant_spec = str(path.parent / plant_spec)
        gains_path = str(path.parent / str(entry["gains"]))
        cache_key = (plant_spec, gains_path)
        if cache_key not in models:
            models[cache_key] = load_model(plant_spec, gains_path, force)
        by_sysid[int(name)] = models[cache_key]
    return Fleet(default, by_sysid)


class Vehicle:
    """One vehicle's loop: estimator state, alarm, observed delay, where to answer, what it last said."""

    __slots__ = ("sysid", "model", "state", "alarm", "delay", "peer", "last_seen", "processed", "duplicates",
                 "stale", "skipped")

    def __init__(self, sysid: int, model: VehicleModel, alarm: AlarmConfig, peer: object, now: float) -> None:
        self.sysid = sysid
        self.model = model
        self.state: EstimatorState = model.estimator.initial_state()
        self.alarm = Alarm(alarm)
        self.delay = DelayTracker()
        self.peer = peer
        self.last_seen = now
        self.processed = self.duplicates = self.stale = self.skipped = 0


@dataclass
class TableCounters:
    processed: int = 0
    duplicates: int = 0
    stale: int = 0
    skipped: int = 0  # samples never received, predicted over by the estimator
    refused: int = 0  # samples from system ids with no model
    vehicles_seen: int = 0
    vehicles_expired: int = 0
    restarts: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Processed:
    """The outcome of one processed sample, for the reply, the publishers and the recorder."""

    __slots__ = ("vehicle", "result", "t", "tau_obs", "alarm_event", "f_mag")

    def __init__(self, vehicle: Vehicle, result: StepResult, t: float, tau_obs: float | None,
                 alarm_event: str | None, f_mag: float) -> None:
        self.vehicle = vehicle
        self.result = result
        self.t = t
        self.tau_obs = tau_obs
        self.alarm_event = alarm_event
        self.f_mag = f_mag


class VehicleTable:
    """Routes telemetry to each vehicle's estimator; the only place that creates or drops vehicles."""

    def __init__(self, fleet: Fleet, alarm: AlarmConfig, timeout: float = 10.0, restart_silence: float = 1.0) -> None:
        self.fleet = fleet
        self.alarm = alarm
        self.timeout = timeout
        self.restart_silence = min(restart_silence, timeout)
        self.vehicles: dict[int, Vehicle] = {}
        self.counters = TableCounters()
        self._refused_logged: set[int] = set()

    def _create(self, sysid: int, peer: object, now: float) -> Vehicle | None:
        model = self.fleet.model_for(sysid)
        if model is None:
            self.counters.refused += 1
            if sysid not in self._refused_logged:
                self._refused_logged.add(sysid)
                log.warning("refusing vehicle sysid %d from %s: no plant/gains for it (fleet file or --plant/--gains)",
                            sysid, peer)
            return None
        vehicle = self.vehicles[sysid] = Vehicle(sysid, model, self.alarm, peer, now)
        self.counters.vehicles_seen += 1
        log.info("vehicle sysid %d from %s: new estimator (plant %s)", sysid, peer, model.plant.name)
        return vehicle

    def accept(self, tel: Telemetry, peer: object, now: float, wall: float) -> Processed | None:
        """Process one sample unless it is a duplicate, stale, or from a refused vehicle (then None)."""
        vehicle = self.vehicles.get(tel.sysid)
        if vehicle is None:
            vehicle = self._create(tel.sysid, peer, now)
            if vehicle is None:
                return None
        model = vehicle.model
        h = model.plant.h
        k = int(round(tel.time_usec / (h * 1e6)))
        k_last = vehicle.state.k_last
        if k_last is not None and k <= k_last:
            if peer != vehicle.peer and now - vehicle.last_seen >= self.restart_silence and k < k_last:
                log.info("vehicle sysid %d restarted (new peer %s, k %d -> %d): fresh estimator",
                         tel.sysid, peer, k_last, k)
                self.counters.restarts += 1
                del self.vehicles[tel.sysid]
                return self.accept(tel, peer, now, wall)
            if k == k_last:
                vehicle.duplicates += 1
                self.counters.duplicates += 1
            else:
                vehicle.stale += 1
                self.counters.stale += 1
            return None
        vehicle.peer = peer
        vehicle.last_seen = now
        a, q = tel.alpha_deg, tel.q_deg_s
        y = [c0 * a + c1 * q for c0, c1 in model.C_rows]
        result = model.estimator.step(vehicle.state, k, y)
        vehicle.processed += 1
        self.counters.processed += 1
        if result.skipped:
            vehicle.skipped += result.skipped
            self.counters.skipped += result.skipped
        t = k * h
        f_mag = max(abs(float(f)) for f in result.f_hat)
        event = vehicle.alarm.update(f_mag)
        tau_obs = vehicle.delay.update(t, wall)
        return Processed(vehicle, result, t, tau_obs, event, f_mag)

    def expire(self, now: float) -> list[int]:
        """Drop vehicles silent for ``timeout`` seconds; returns their system ids."""
        gone = [s for s, v in self.vehicles.items() if now - v.last_seen > self.timeout]
        for sysid in gone:
            v = self.vehicles.pop(sysid)
            self.counters.vehicles_expired += 1
            log.info("vehicle sysid %d silent for %.1f s: dropped after %d samples", sysid, self.timeout, v.processed)
        return gone
