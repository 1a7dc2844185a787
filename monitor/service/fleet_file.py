"""Fleet and model files: which plant, gains and signal map serve a system id.

A model is a plant, its gains (cross-checked against the plant's hash), its signal map and the estimator
built from them. The fleet config is TOML, one ``[vehicle.<sysid>]`` table each with ``plant``, ``gains``
and optionally ``signals``; a system id it does not list gets the default ``--plant``/``--gains`` model, if
any. ``load_model`` loads one model, ``load_fleet`` a fleet file of them; the vehicle table
(``monitor.service.vehicles``) serves what they load.
"""

from __future__ import annotations

import logging
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.gains import GainsFile, read_gains
from monitor.link.signals import MAVLINK, Layouts, SignalMap, signals_for_plant
from monitor.model.estimator import Estimator
from monitor.model.plant import Plant, load_plant

__all__ = ["VehicleModel", "Fleet", "load_model", "load_fleet"]

log = logging.getLogger("monitor.service.vehicles")  # the --force warning's logger name predates the split


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """A plant, its gains, its signal map and the estimator built from them (shared between vehicles)."""

    plant: Plant
    gains: GainsFile
    estimator: Estimator
    signals: SignalMap

    @property
    def h(self) -> float:
        return self.plant.h


def load_model(
    plant_spec: str | Path,
    gains_path: str | Path,
    force: bool = False,
    signals_file: str | Path | None = None,
    layouts: Layouts = MAVLINK,
) -> VehicleModel:
    """Load and cross-check a plant and its gains; a plant-hash mismatch is a UserError unless ``force``.

    ``layouts``: where the signal map's message names are looked up (a DataFlash log's own, for ``analyse``)."""
    plant = load_plant(plant_spec)
    gains = read_gains(gains_path)
    gains.check_plant(plant)
    designed_for = gains.meta.get("plant_hash")
    if designed_for != plant.digest:
        what = (
            f"{gains_path}: designed for plant {designed_for or '(no hash recorded)'}, "
            f"not for {plant_spec} ({plant.digest})"
        )
        if not force:
            raise UserError(f"{what}; use --force to run it anyway")
        log.warning("%s; running anyway (--force)", what)
    signals = signals_for_plant(plant, signals_file, layouts)
    limit = plant.actuator.limit
    if limit is not None:
        for name, u0 in zip(signals.actuator, signals.u0, strict=True):
            if not abs(u0) < limit:
                raise UserError(
                    f"{signals.source}: [signals] operating_point: '{name}' = {u0:g} is not inside the "
                    f"actuator limit +-{limit:g} of plant {plant.name}"
                )
    return VehicleModel(
        plant,
        gains,
        Estimator(plant, gains.gains, u0=signals.u0, fault_time_constant=gains.fault_time_constant),
        signals,
    )


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
