"""Settings of one vehicle run: command-line flags, optionally preset from a TOML vehicle file.

A vehicle file holds the same names as the long flags (``-`` or ``_``), e.g.::

    plant = "paper-continuous"
    sysid = 3
    fault = "bias:2@20"
    delay = "normal:0.2:0.05"
    loss = 0.02
    zenoh_connect = ["tcp/127.0.0.1:7447"]

or, for a JSBSim aircraft::

    aircraft = "c172p"
    airspeed = 100
    altitude = 3000
    rate = 20
    turbulence = "light"
    excite = "prbs:1:60"

or an aircraft flying a mission (``docs/missions.md``)::

    aircraft = "c172p"
    mission = "docs/examples/mission-manoeuvres.toml"
    compensation = true

Flags given on the command line win over the file. Why strict: an unknown key (``dealy``) silently
ignored would run a different experiment than the one written down, so it is an error. The file is
read by ``monitor.config_file``, the same reader as ``fault-monitor run --config``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from monitor.config_file import apply_config_file  # the one reader of --config files (also fault-monitor run)
from monitor.errors import UserError
from monitor.model.plant import Plant, load_plant
from monitor.wire import TURBULENCE_LEVELS
from monitor.wire.specs import (
    DelaySampler,
    Excitation,
    FaultSchedule,
    Wind,
    parse_delay_spec,
    parse_excite_spec,
    parse_fault_spec,
    parse_wind_spec,
)
from sim_vehicle.network import Impairment

if TYPE_CHECKING:
    from sim_vehicle.jsbsim_model import AircraftSpec  # imported lazily at run time (JSBSim runs only)

__all__ = ["Settings", "apply_config_file", "settings_from_args", "parse_udpout", "parse_hostport"]


@dataclass(frozen=True)
class Settings:
    """Everything a run needs, validated. Exactly one of ``plant`` (linear) and ``aircraft`` (JSBSim) is set."""

    plant: Plant | None
    sysid: int
    steps: int | None
    speedup: float
    fault: FaultSchedule
    delay: DelaySampler
    delay_split: float
    impairment: Impairment
    wind: Wind
    sensor_noise: float
    seed: int
    x0: list[float] | None
    target: tuple[str, int]
    bind: tuple[str, int]
    autopilot: np.ndarray | None = None
    aircraft: AircraftSpec | None = None
    excite: Excitation | None = None
    compensation: bool = False  # a mission: commands from outside add to the autopilot's elevator

    @property
    def h(self) -> float:
        if self.aircraft is not None:
            return self.aircraft.h
        assert self.plant is not None  # exactly one of plant and aircraft is set
        return self.plant.h

    @property
    def vehicle(self) -> str:
        """What flies, for log lines."""
        if self.aircraft is not None:
            return f"aircraft {self.aircraft.name}"
        assert self.plant is not None  # exactly one of plant and aircraft is set
        return f"plant {self.plant.name}"


AIRCRAFT_DEFAULTS = {"airspeed": 100.0, "altitude": 3000.0, "rate": 20.0, "turbulence": "none"}


def parse_hostport(text: str, what: str) -> tuple[str, int]:
    host, sep, port = str(text).rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"{what} '{text}': expected HOST:PORT, e.g. 127.0.0.1:14550")
    return host, int(port)


def parse_udpout(text: str) -> tuple[str, int]:
    """``udpout:HOST:PORT`` (MAVProxy's spelling) -> ``(HOST, PORT)``; ``udp:`` is accepted as an alias."""
    scheme, sep, rest = str(text).partition(":")
    if not sep or scheme not in ("udpout", "udp"):
        raise UserError(f"--mavlink '{text}': expected udpout:HOST:PORT (the vehicle sends to the monitor's udpin)")
    return parse_hostport(rest, "--mavlink")


def _probability(value, name: str) -> float:
    value = _number(value, name)
    if not 0.0 <= value <= 1.0:
        raise UserError(f"--{name} must be in [0, 1], got {value:g}")
    return value


def _number(value, name: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise UserError(f"--{name} must be a number, got {value!r}") from None


def _aircraft_spec(args: argparse.Namespace, seed: int):
    """``--aircraft`` and its flags -> ``AircraftSpec`` (no JSBSim import: loading and trimming come later)."""
    from sim_vehicle.jsbsim_model import DEFAULT_DT, AircraftSpec

    name = str(args.aircraft)
    mission = _mission(args)
    for flag in ("plant", "wind", "x0", "autopilot"):
        if getattr(args, flag, None) is not None:
            why = {
                "plant": "one vehicle flies either a plant or an aircraft",
                "wind": "the aircraft flies in JSBSim's weather: use --turbulence",
                "x0": "the aircraft starts trimmed (--airspeed, --altitude)",
                "autopilot": "the on-board gain is for the linear plant; --excite flies an aircraft on board",
            }[flag]
            raise UserError(f"--{flag.replace('_', '-')} does not go with --aircraft: {why}")
    value = {k: AIRCRAFT_DEFAULTS[k] if getattr(args, k, None) is None else getattr(args, k) for k in AIRCRAFT_DEFAULTS}
    if mission is not None:  # trimmed where the mission starts
        first = mission.segments[0]
        value["airspeed"], value["altitude"] = first.airspeed_kt, first.altitude_ft
    airspeed, altitude, rate = (_number(value[k], k) for k in ("airspeed", "altitude", "rate"))
    for flag, v in (("airspeed", airspeed), ("altitude", altitude), ("rate", rate)):
        if not (v > 0 and np.isfinite(v)):
            raise UserError(f"--{flag} must be positive, got {v:g}")
    dt = DEFAULT_DT if getattr(args, "dt", None) is None else _number(args.dt, "dt")
    if not 0 < dt <= 0.1:
        raise UserError(f"--dt must be in (0, 0.1] seconds, got {dt:g}")
    turbulence = str(value["turbulence"]).strip().lower()
    if turbulence not in TURBULENCE_LEVELS:
        raise UserError(f"--turbulence must be one of {', '.join(TURBULENCE_LEVELS)}, got '{value['turbulence']}'")
    return AircraftSpec(
        name=name,
        aircraft_dir=getattr(args, "aircraft_dir", None),
        airspeed_kt=airspeed,
        altitude_ft=altitude,
        h=1.0 / rate,
        dt=dt,
        turbulence=turbulence,
        seed=seed,
        mission=mission,
    )


def _mission(args: argparse.Namespace):  # -> Mission | None (imported lazily, with the aircraft's modules)
    """``--mission FILE`` read and checked, or None; the flags a mission replaces are refused, one line each."""
    path = getattr(args, "mission", None)
    if path is None:
        return None
    from sim_vehicle.mission import load_mission

    for flag, why in (
        ("excite", "give a segment an excite key instead (a PRBS on the autopilot's elevator)"),
        ("airspeed", "the aircraft is trimmed at the first segment's airspeed"),
        ("altitude", "the aircraft is trimmed at the first segment's altitude"),
    ):
        if getattr(args, flag, None) is not None:
            raise UserError(f"--{flag} does not go with --mission: {why}")
    return load_mission(path)


def settings_from_args(args: argparse.Namespace) -> Settings:
    """Validate the parsed flags into ``Settings`` (one-line ``UserError`` on anything wrong)."""
    seed = int(args.seed)
    aircraft = None
    if getattr(args, "mission", None) is not None:
        if getattr(args, "aircraft", None) is None:
            raise UserError("--mission needs --aircraft NAME: a JSBSim aircraft's autopilot flies it")
        if getattr(args, "autopilot", None) is not None:
            raise UserError("--autopilot does not go with --mission: the aircraft's own autopilot flies the mission")
    elif getattr(args, "compensation", False):
        raise UserError("--compensation goes with --mission: it adds to the mission autopilot's elevator")
    if getattr(args, "aircraft", None) is not None:
        aircraft = _aircraft_spec(args, seed)
        plant, h = None, aircraft.h
    else:
        for flag in ("aircraft_dir", *AIRCRAFT_DEFAULTS, "dt"):
            if getattr(args, flag, None) is not None:
                raise UserError(f"--{flag.replace('_', '-')} goes with --aircraft NAME (a JSBSim aircraft)")
        plant = load_plant(args.plant or "paper-continuous")
        if plant.continuous is None:
            raise UserError(f"--plant {args.plant}: the simulator needs a continuous plant (try paper-continuous)")
        h = plant.h
    sysid = int(args.sysid)
    if not 1 <= sysid <= 255:
        raise UserError(f"--sysid must be in 1..255 (MAVLink system ids), got {sysid}")
    steps = None if args.steps in (None, 0) else int(args.steps)
    if steps is not None and steps < 0:
        raise UserError(f"--steps must be positive (0: until a signal), got {steps}")
    if aircraft is not None and aircraft.mission is not None:  # the mission's length, unless --steps is shorter
        steps = min(steps or aircraft.mission.steps(h), aircraft.mission.steps(h))
    speedup = _number(args.speedup, "speedup")
    if not speedup > 0:
        raise UserError(f"--speedup must be positive, got {speedup:g}")
    # CONTRACT.md's default, uniform:0:0.46 for h = 1 s, kept inside the plant's own delay interval
    if plant is not None:
        delay_text = args.delay or f"uniform:{plant.tau_min:g}:{min(0.46 * plant.h, plant.tau_max):g}"
    else:
        delay_text = args.delay or f"uniform:0:{0.46 * h:g}"
    x0 = None
    if args.x0 is not None and plant is not None:
        parts = args.x0 if isinstance(args.x0, list) else str(args.x0).split(",")
        x0 = [_number(v, "x0") for v in parts]
        if len(x0) != plant.n:
            raise UserError(f"--x0 needs {plant.n} comma-separated values (the state), got {len(x0)}")
    noise = _number(args.sensor_noise, "sensor-noise")
    if noise < 0:
        raise UserError(f"--sensor-noise must be >= 0, got {noise:g}")
    excite = parse_excite_spec(getattr(args, "excite", None))
    if excite is not None and getattr(args, "autopilot", None) is not None:
        raise UserError("--excite and --autopilot both fly the vehicle on board: choose one")
    return Settings(
        plant=plant,
        sysid=sysid,
        steps=steps,
        speedup=speedup,
        fault=parse_fault_spec(args.fault),
        delay=parse_delay_spec(delay_text, seed=seed),
        delay_split=_probability(args.delay_split, "delay-split"),
        impairment=Impairment(
            loss=_probability(args.loss, "loss"),
            duplicate=_probability(args.duplicate, "duplicate"),
            reorder=_probability(args.reorder, "reorder"),
            h=h,
            seed=seed,
        ),
        wind=parse_wind_spec(args.wind or "paper", h, seed) if plant is not None else Wind(oscillator=False, h=h),
        sensor_noise=noise,
        seed=seed,
        x0=x0,
        target=parse_udpout(args.mavlink),
        bind=parse_hostport(args.bind, "--bind"),
        autopilot=_autopilot_gain(getattr(args, "autopilot", None), plant) if plant is not None else None,
        aircraft=aircraft,
        excite=excite,
        compensation=bool(getattr(args, "compensation", False)),
    )


def _autopilot_gain(value, plant: Plant) -> np.ndarray | None:
    """``--autopilot K``: the on-board gain u = K y, one value per plant output (comma-separated)."""
    if value is None:
        return None
    parts = value if isinstance(value, list) else str(value).split(",")
    gain = [_number(v, "autopilot") for v in parts]
    if len(gain) != plant.l or plant.m != 1:
        raise UserError(
            f"--autopilot needs {plant.l} comma-separated gain(s), one per plant output "
            f"(single-input plants only), got {len(gain)}"
        )
    if not all(np.isfinite(gain)):
        raise UserError("--autopilot gains must be finite")
    return np.array([gain])
