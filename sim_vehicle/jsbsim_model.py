"""A JSBSim aircraft as a ``FlightModel``: nonlinear 6-DOF, trimmed by JSBSim, flown at JSBSim's own step.

Loading. ``--aircraft NAME`` is any aircraft JSBSim ships (``c172p``, ``737``, ``J3Cub``...) or, with
``--aircraft-dir DIR``, the user's own: DIR may be a JSBSim root (``DIR/aircraft/NAME/NAME.xml``, with its
``engine/`` and ``systems/``), a directory of aircraft (``DIR/NAME/NAME.xml``; engines and systems then come
from JSBSim's bundled set unless the aircraft has its own), or the aircraft's own folder (``DIR/NAME.xml``).

Trim. Level flight (flight-path angle 0) at ``--airspeed`` knots calibrated and ``--altitude`` feet above sea
level, engines running, JSBSim's full trim (``simulation/do_simple_trim = 1``: throttle, elevator via the pitch
trim, aileron, rudder, attitude). Where that fails, the aircraft is trimmed by flying it (``_fly_to_trim``: the
on-board autopilot holds the airspeed and altitude until steady); an aircraft that neither trims nor settles is
a ``UserError`` quoting JSBSim's ``TrimFailureError``, the reason JSBSim printed (e.g. "udot doesn't appear to be
trimmable") and what the autopilot found (a stall, a throttle on its stop).

The elevator. The servo (``sim_vehicle.dynamics.Airframe``) works in absolute degrees of surface deflection,
trim included, so the surface is driven by deflection, not by stick. JSBSim's aerodynamics read
``fcs/elevator-pos-rad``, which the aircraft's own flight-control system writes on every step: writing it
from outside has no effect (tested on c172p, 737 and J3Cub: the next step overwrites it). So the deflection is
commanded through ``fcs/elevator-cmd-norm`` with the aircraft's own scaling, found numerically: a second,
throw-away instance of the same aircraft, trimmed the same way, is probed with integration suspended for the
deflection each command in [-1, 1] gives (81 points; c172p: -28 deg at -1, +23 deg at +1, piecewise linear).
Probing the flying instance instead is not harmless: JSBSim's multi-step integrators keep the accelerations
of the probe in their history (measured: q wandered to 0.08 deg/s instead of 7e-4 deg/s in 10 s at trim).
After the trim, the pitch trim JSBSim set is moved into the command (``pitch-trim-cmd-norm`` = 0, the command
= their sum), which leaves the surface where it was. A deflection is then turned into a command by
interpolating the probed map; the travel the map spans is the servo's travel. An aircraft whose map is not
monotone, spans less than a degree, or does not reproduce the trim deflection (a fly-by-wire pitch channel
such as the f16's) is refused. The deflection acting includes the additive fault (``bias``/``ramp`` act at the
surface, after the servo) and is read back from ``fcs/elevator-pos-deg`` for the truth stream.

Time. JSBSim integrates at a fixed step ``dt`` (1/120 s unless ``--dt``; made the largest step not above it
that divides h, so every sampling instant k h is a step boundary). An event at time t takes effect at the
step boundary nearest t (at most dt/2 away); states are read as JSBSim left them after its last step.

A mission (``AircraftSpec.mission``). The aircraft is flown by the on-board autopilot (``sim_vehicle/autopilot.py``),
stepped at every JSBSim step inside ``fly``, which replaces ``step``: the autopilot writes aileron, rudder and
throttle and returns its elevator, the servo adds the compensation received from outside and clips to the travel,
and the surface faults act on that. The autopilot's view of what the aircraft cannot do (a stall, the throttle on
a stop with the airspeed off) raises ``FlightModelError`` naming the segment. The stall alpha comes from JSBSim's
``aero/alpha-max-rad`` or the aircraft's lift table (``stall_alpha``).

Turbulence: JSBSim's MIL-F-8785C Dryden model (``atmosphere/turb-type`` = 3, "Milspec") with the intensities
JSBSim documents in FGWinds.h: light 25 ft/s at 20 ft AGL and probability-of-exceedance curve 3, moderate
50 ft/s and 4, severe 75 ft/s and 6. Its random generator is seeded from ``--seed`` through
``simulation/randomseed`` (a minimal-standard LCG: seeds 0 and 1 would be the same stream, so seed s is
mapped to 1 + s mod (2^31 - 2)). Same seed, same flight, to the bit (tested).

JSBSim is imported here, lazily, so that ``import sim_vehicle`` and ``sim-vehicle --help`` never load it, and
everything it says while loading and trimming (its loading and trim messages) is collected by a JSBSim logger of
our own, logged at DEBUG, and kept off the daemon's stdout.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from monitor.errors import UserError
from monitor.wire import TURBULENCE_INTENSITY  # (windspeed at 20 ft AGL, PoE curve) per level: JSBSim's table
from sim_vehicle.flight_model import FlightModelError, Outputs

if TYPE_CHECKING:
    from sim_vehicle.autopilot import Autopilot
    from sim_vehicle.mission import Mission, Timeline

__all__ = [
    "AircraftSpec",
    "JSBSimFlightModel",
    "DEFAULT_DT",
    "DEFAULT_STALL_ALPHA_DEG",
    "jsbsim_seed",
    "step_size",
    "stall_alpha",
]

log = logging.getLogger(__name__)

DEFAULT_DT = 1.0 / 120.0
KT_TO_M_S = 1852.0 / 3600.0
FT_TO_M = 0.3048
MILSPEC = 3  # atmosphere/turb-type: ttMilspec (Dryden spectrum, MIL-F-8785C)
_PROBE = np.linspace(-1.0, 1.0, 81)  # commands probed for the elevator's scaling (0 and the ends included)
_LCG_MODULUS = 2**31 - 1
DEFAULT_STALL_ALPHA_DEG = 15.0  # when the aircraft's files say nothing (a light aircraft's stall is 14-18 deg)
# trimmed by flying (``_fly_to_trim``), when JSBSim's trim fails: steady this long within these, in at most MAX_S
FLOWN_TRIM_MAX_S = 150.0
FLOWN_TRIM_STOP_S = 60.0  # the autopilot's throttle-on-a-stop watch, this long after it fired: the engine cannot
FLOWN_TRIM_STEADY_S = 5.0
FLOWN_TRIM_CLIMB_FPM = 20.0
FLOWN_TRIM_ALTITUDE_FT = 20.0
FLOWN_TRIM_RATE_DEG_S = 0.1
FLOWN_TRIM_BANK_DEG = 0.5
FLOWN_TRIM_THROTTLE = 0.6  # where the throttle starts; its integral finds the rest


@dataclass(frozen=True)
class AircraftSpec:
    """What to fly and where: everything ``JSBSimFlightModel`` needs, validated by the caller."""

    name: str
    aircraft_dir: str | None = None
    airspeed_kt: float = 100.0
    altitude_ft: float = 3000.0
    h: float = 0.05
    dt: float = DEFAULT_DT
    turbulence: str = "none"
    seed: int = 0
    mission: Mission | None = None  # flown by the on-board autopilot (sim_vehicle/autopilot.py)


def jsbsim_seed(seed: int) -> int:
    """``--seed`` -> ``simulation/randomseed``: distinct for distinct seeds below 2^31 - 2, never 0 (== 1)."""
    return 1 + int(seed) % (_LCG_MODULUS - 1)


def step_size(h: float, dt: float = DEFAULT_DT) -> float:
    """The largest step not above ``dt`` that divides ``h`` (so every sampling instant is a step boundary)."""
    return h / max(1, math.ceil(h / dt - 1e-9))


def _import_jsbsim():
    try:
        import jsbsim
    except ImportError:  # pragma: no cover - jsbsim is a dependency
        raise UserError("--aircraft needs the jsbsim package (pip install 'jsbsim>=1.3.3,<1.4')") from None
    jsbsim.FGJSBBase().debug_lvl = 0  # no banner on construction (a class-wide switch)
    # what JSBSim says in flight goes to the log (stderr), never to stdout: its default logger prints
    jsbsim.set_logger(_logger_class(jsbsim)(_log_record))
    return jsbsim


@functools.cache
def _logger_class(jsbsim):  # noqa: ANN001, ANN202 - the lazily imported module and a class made from it
    """An ``FGLogger`` that hands each finished record (its text) to a Python callable (the class made once)."""

    class RecordLogger(jsbsim.FGLogger):  # type: ignore[name-defined]  # a base from the module given at run time
        def __init__(self, on_record: Callable[[str], None]) -> None:
            super().__init__()
            self._on_record = on_record
            self._parts: list[str] = []

        def set_level(self, level) -> None:  # noqa: ANN001
            self._parts = []

        def file_location(self, filename: str, line: int) -> None:
            pass

        def message(self, message: str) -> None:
            self._parts.append(message)

        def format(self, format) -> None:  # noqa: A002, ANN001 - JSBSim's own argument name
            pass

        def flush(self) -> None:
            text, self._parts = "".join(self._parts), []
            if text.strip():
                self._on_record(text)

    return RecordLogger


def _log_record(text: str) -> None:
    log.info("JSBSim: %s", " ".join(text.split()))


@contextlib.contextmanager
def _jsbsim_messages(jsbsim) -> Iterator[list[str]]:  # noqa: ANN001
    """Collect what JSBSim logs inside the block; the text is in the yielded list afterwards.

    Why a logger and not file descriptor 1: JSBSim 1.3 routes its messages through an ``FGLogger`` whose
    default prints with Python's ``print``. Captured at the descriptor, a message sat in ``sys.stdout``'s
    buffer whenever stdout was a pipe without ``PYTHONUNBUFFERED`` and reached the daemon's stdout at exit,
    whatever the timing. A logger of our own receives each record as it is made, so nothing can leak.
    JSBSim keeps one logger per thread: the one in place before the block is put back after it.
    """
    records: list[str] = []
    logger = _logger_class(jsbsim)(records.append)
    previous = jsbsim.get_logger()
    jsbsim.set_logger(logger)
    box: list[str] = []
    try:
        yield box
    finally:
        logger.flush()
        jsbsim.set_logger(previous)
        box.append("".join(records))


def _reason(printed: str) -> str:
    """The last line JSBSim printed that says something, for a one-line error."""
    lines = [" ".join(line.split()) for line in printed.splitlines()]
    lines = [line for line in lines if line and not line.startswith(("JSBSim", "[JSBSim"))]
    return lines[-1] if lines else ""


def _locate(name: str, aircraft_dir: str | None, bundled_root: Path) -> tuple[Path, Path | None, bool]:
    """``(root_dir, aircraft_path or None, add_model_to_path)`` for ``load_model_with_paths``."""
    if not name or name != Path(name).name or name.startswith("."):
        raise UserError(f"--aircraft '{name}': expected an aircraft name such as c172p (use --aircraft-dir for a path)")
    if aircraft_dir is None:
        if not (bundled_root / "aircraft" / name / f"{name}.xml").is_file():
            raise UserError(
                f"--aircraft {name}: JSBSim has no such aircraft (no {name}/{name}.xml in "
                f"{bundled_root / 'aircraft'}); e.g. c172p, 737, J3Cub, or --aircraft-dir DIR"
            )
        return bundled_root, None, True
    base = Path(aircraft_dir).expanduser().resolve()
    if not base.is_dir():
        raise UserError(f"--aircraft-dir {aircraft_dir}: not a directory")
    if (base / "aircraft" / name / f"{name}.xml").is_file():
        return base, None, True  # a JSBSim root with its own engine/ and systems/
    if (base / name / f"{name}.xml").is_file():
        return bundled_root, base, True
    if (base / f"{name}.xml").is_file():
        return bundled_root, base, False
    raise UserError(
        f"--aircraft {name}: no {name}.xml in --aircraft-dir {aircraft_dir} (looked for "
        f"aircraft/{name}/{name}.xml, {name}/{name}.xml and {name}.xml)"
    )


def _aircraft_xml(spec: AircraftSpec, bundled_root: Path) -> Path:
    """The file that defines the aircraft (where ``_locate`` finds it)."""
    root, aircraft_path, add_name = _locate(spec.name, spec.aircraft_dir, bundled_root)
    if aircraft_path is None:
        return root / "aircraft" / spec.name / f"{spec.name}.xml"
    return aircraft_path / spec.name / f"{spec.name}.xml" if add_name else aircraft_path / f"{spec.name}.xml"


def stall_alpha(fdm, xml: Path | None) -> tuple[float, str]:  # noqa: ANN001 - a jsbsim.FGFDMExec
    """The aircraft's stall angle of attack (deg) and where it comes from.

    In order: JSBSim's ``aero/alpha-max-rad``, which an aircraft defining ``<alphalimits>`` sets (c172p:
    0.28 rad = 16.0 deg); else the angle of attack at the peak of the lift table in the aircraft's LIFT axis
    (the table looked up by alpha with the largest peak, its first column; J3Cub: 12.5 deg); else
    ``DEFAULT_STALL_ALPHA_DEG`` (15 deg).
    """
    limit = float(fdm["aero/alpha-max-rad"])
    if limit > 0:
        return math.degrees(limit), "aero/alpha-max-rad"
    peak = _lift_peak_deg(xml) if xml is not None else None
    if peak is not None:
        return peak, "the peak of its lift table"
    return DEFAULT_STALL_ALPHA_DEG, "the default"


def _lift_peak_deg(xml: Path) -> float | None:
    """Alpha (deg) at the peak of the aircraft's lift-vs-alpha table, or None when its file has no such table."""
    try:
        tree = ET.parse(xml)
    except (OSError, ET.ParseError):
        return None
    best: tuple[float, float] | None = None  # (peak lift coefficient, its alpha in degrees)
    for axis in tree.getroot().iter("axis"):
        if axis.get("name", "").upper() != "LIFT":
            continue
        for table in axis.iter("table"):
            keys = table.findall("independentVar")
            rows = [k for k in keys if k.get("lookup", "row") == "row"]
            var = (rows[0].text or "").strip() if rows else ""
            data = table.find("tableData")
            if var not in ("aero/alpha-rad", "aero/alpha-deg") or data is None:
                continue
            try:
                lines = [[float(v) for v in line.split()] for line in (data.text or "").splitlines() if line.split()]
            except ValueError:
                continue
            points = [(line[0], line[1]) for line in lines[1 if len(keys) > 1 else 0 :] if len(line) >= 2]
            if len(points) < 3:
                continue
            i = max(range(len(points)), key=lambda j: points[j][1])
            alpha = math.degrees(points[i][0]) if var == "aero/alpha-rad" else points[i][0]
            if 0 < i < len(points) - 1 and 0.0 < alpha < 45.0 and (best is None or points[i][1] > best[0]):
                best = (points[i][1], alpha)
    return None if best is None else best[1]


def _load(jsbsim, spec: AircraftSpec):
    """An FDM instance of ``spec`` at its initial conditions, engines running, not trimmed (a ``UserError`` naming
    the reason when JSBSim cannot load it)."""
    bundled = Path(jsbsim.get_default_root_dir())
    root, aircraft_path, add_name = _locate(spec.name, spec.aircraft_dir, bundled)
    what = f"--aircraft {spec.name}"
    with _jsbsim_messages(jsbsim) as printed:
        fdm = jsbsim.FGFDMExec(str(root))
        fdm.set_debug_level(0)
        try:
            if aircraft_path is None:
                loaded = fdm.load_model(spec.name)
            else:
                loaded = fdm.load_model_with_paths(
                    spec.name, str(aircraft_path), str(root / "engine"), str(root / "systems"), add_name
                )
        except jsbsim.BaseError as exc:
            loaded, error = False, str(exc)
        else:
            error = ""
    log.debug("JSBSim loading %s: %s", spec.name, printed[0].strip())
    if not loaded:
        why = error or _reason(printed[0]) or "JSBSim could not load it"
        raise UserError(f"{what}: JSBSim cannot load it: {why}")
    fdm.set_dt(spec.dt)
    fdm["simulation/randomseed"] = jsbsim_seed(spec.seed)
    fdm["ic/h-sl-ft"] = spec.altitude_ft
    fdm["ic/vc-kts"] = spec.airspeed_kt
    fdm["ic/gamma-deg"] = 0.0
    return fdm


def _engines_on(fdm) -> int:  # noqa: ANN001 - an FGFDMExec
    """Every engine running as a pilot runs it in flight: mixture rich, both magnetos, a constant-speed propeller
    at its highest rpm. Why: JSBSim's ``set-running`` alone leaves the magnetos off, and a piston engine then gives
    less power (pa28: 98 kt at full throttle, where with them it holds 100 kt at 0.84). No change on c172p,
    t6texan2 or J3Cub (their trims are the same to the last digit). Returns the number of engines."""
    engines = max(1, int(fdm.get_propulsion().get_num_engines()))
    for i in range(engines):
        fdm[f"fcs/mixture-cmd-norm[{i}]"] = 1.0
        fdm[f"fcs/advance-cmd-norm[{i}]"] = 1.0
    fdm["propulsion/magneto_cmd"] = 3
    fdm["propulsion/set-running"] = -1
    return engines


def _where(spec: AircraftSpec) -> str:
    return f"{spec.airspeed_kt:g} kt, {spec.altitude_ft:g} ft"


def _jsbsim_trim(jsbsim, fdm, spec: AircraftSpec) -> str:  # noqa: ANN001 - the lazily imported module, an FGFDMExec
    """Run the initial conditions and JSBSim's full trim on ``fdm``; "" when it trimmed, else why it did not."""
    with _jsbsim_messages(jsbsim) as printed:
        try:
            fdm.run_ic()
            _engines_on(fdm)
            fdm["simulation/do_simple_trim"] = 1  # full trim
        except jsbsim.TrimFailureError as exc:
            failure = f"{exc}"
        except (jsbsim.BaseError, RuntimeError, KeyError) as exc:
            failure = f"{type(exc).__name__}: {exc}"
        else:
            failure = ""
    log.debug("JSBSim trimming %s at %s: %s", spec.name, _where(spec), printed[0].strip())
    if failure:
        detail = _reason(printed[0])
        return failure + (f" ({detail})" if detail else "")
    alpha, airspeed = fdm["aero/alpha-deg"], fdm["velocities/vc-kts"]
    if not (math.isfinite(alpha) and abs(airspeed - spec.airspeed_kt) < _airspeed_tolerance(spec)):
        return f"JSBSim reports alpha {alpha:g} deg at {airspeed:g} kt"
    return ""


def _airspeed_tolerance(spec: AircraftSpec) -> float:
    return 0.01 * spec.airspeed_kt + 0.5


def _load_and_trim(jsbsim, spec: AircraftSpec):
    """A trimmed FDM instance of ``spec`` by JSBSim's trim (a ``UserError`` naming the reason when it cannot be
    had); the flight model falls back on ``_fly_to_trim`` itself, as that needs the elevator's map."""
    fdm = _load(jsbsim, spec)
    failure = _jsbsim_trim(jsbsim, fdm, spec)
    if failure:
        raise UserError(f"--aircraft {spec.name} does not trim at {_where(spec)}: {failure}")
    return fdm


def _fly_to_trim(  # noqa: ANN001 - an FGFDMExec
    fdm, spec: AircraftSpec, commands: np.ndarray, deflections: np.ndarray, stall_alpha_deg: float, failure: str
) -> None:
    """Trim by flying: the on-board autopilot holds ``spec``'s airspeed and altitude, wings level, until the
    aircraft is steady (``FLOWN_TRIM_STEADY_S`` within the tolerances below), at most ``FLOWN_TRIM_MAX_S``.

    Why: JSBSim's trim fails on aircraft that fly perfectly well, piston-engined ones with their magnetos on most
    (pa28, c310: "udot doesn't appear to be trimmable"; its steady-state engine loop freezes the inputs the
    flight-control system computes, JSBSim issue 1440). What is left is the steady state an autopilot finds, with
    its residue: the phugoid's last swing and the airspeed within the tolerance JSBSim's own trim is held to. A
    ``UserError`` when the autopilot cannot settle it either: a stall, a throttle on its stop for
    ``FLOWN_TRIM_STOP_S`` after the autopilot's own watch (5 s) fired (a turbine spools up for tens of seconds
    from the initial conditions), or no steady state in time."""
    from sim_vehicle.autopilot import Autopilot, Targets, Trim

    where = f"--aircraft {spec.name} does not trim at {_where(spec)}"
    fdm.run_ic()
    engines = _engines_on(fdm)
    fdm["fcs/pitch-trim-cmd-norm"] = 0.0
    increasing = np.argsort(deflections, kind="stable")
    deg, cmd = deflections[increasing], commands[increasing]
    trim = Trim(
        elevator_deg=float(np.interp(0.0, commands, deflections)),
        aileron=0.0,
        rudder=0.0,
        throttle=FLOWN_TRIM_THROTTLE,
        theta_deg=fdm["attitude/theta-deg"],
        airspeed_kt=spec.airspeed_kt,
        altitude_ft=spec.altitude_ft,
        qbar_psf=fdm["aero/qbar-psf"],
    )
    throttles = tuple("fcs/throttle-cmd-norm" + (f"[{i}]" if i else "") for i in range(engines))
    dt = float(fdm.get_delta_t())
    pilot = Autopilot(trim, (float(deg[0]), float(deg[-1])), dt, stall_alpha_deg, throttles=throttles)
    targets = Targets(airspeed_kt=spec.airspeed_kt, altitude_ft=spec.altitude_ft, bank_deg=0.0)
    tolerance = _airspeed_tolerance(spec)
    steady, troubled = 0.0, 0.0
    for _ in range(int(FLOWN_TRIM_MAX_S / dt)):
        fdm["fcs/elevator-cmd-norm"] = float(np.interp(pilot.step(fdm, targets), deg, cmd))
        fdm.run()
        trouble = pilot.trouble
        troubled = troubled + dt if trouble is not None else 0.0
        # a stall is final; a throttle on its stop only once it has stayed there (a turbine spools up for tens of
        # seconds from the initial conditions: pc7)
        if trouble is not None and (trouble[0] == "stalls" or troubled >= FLOWN_TRIM_STOP_S):
            raise UserError(
                f"{where}: JSBSim's trim failed ({failure}); flown by the autopilot it {trouble[0]}: {trouble[1]}; "
                f"{fdm['velocities/vc-kts']:.1f} kt after {fdm['simulation/sim-time-sec']:.0f} s"
            )
        settled = (
            abs(fdm["velocities/vc-kts"] - spec.airspeed_kt) < tolerance
            and abs(fdm["velocities/h-dot-fps"]) * 60.0 < FLOWN_TRIM_CLIMB_FPM
            and abs(fdm["position/h-sl-ft"] - spec.altitude_ft) < FLOWN_TRIM_ALTITUDE_FT
            and abs(math.degrees(fdm["velocities/q-rad_sec"])) < FLOWN_TRIM_RATE_DEG_S
            and abs(fdm["attitude/phi-deg"]) < FLOWN_TRIM_BANK_DEG
        )
        steady = steady + dt if settled else 0.0
        if steady >= FLOWN_TRIM_STEADY_S:
            log.info(
                "%s: JSBSim's trim failed (%s); trimmed by flying it (%.0f s of simulated flight, throttle %.2f)",
                spec.name,
                failure,
                fdm["simulation/sim-time-sec"],
                fdm["fcs/throttle-cmd-norm"],
            )
            return
    raise UserError(
        f"{where}: JSBSim's trim failed ({failure}) and flown by the autopilot it was not steady after "
        f"{FLOWN_TRIM_MAX_S:g} s (airspeed {fdm['velocities/vc-kts']:.1f} kt, "
        f"climb {fdm['velocities/h-dot-fps'] * 60.0:.0f} ft/min, throttle {fdm['fcs/throttle-cmd-norm']:.2f})"
    )


def _elevator_map(jsbsim, spec: AircraftSpec, trimmed: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Deflection (deg) per ``fcs/elevator-cmd-norm`` with the pitch trim at 0, from a throw-away instance
    (trimmed as the flying one is by JSBSim's trim; ``trimmed=False``: at its initial conditions, for an aircraft
    JSBSim's trim fails on: the map is the flight-control system's, integration suspended)."""
    probe = _load_and_trim(jsbsim, spec) if trimmed else _load(jsbsim, spec)
    try:
        with _jsbsim_messages(jsbsim):
            if not trimmed:
                probe.run_ic()
            probe.suspend_integration()
            probe["fcs/pitch-trim-cmd-norm"] = 0.0
            deg = []
            for command in _PROBE:
                probe["fcs/elevator-cmd-norm"] = float(command)
                probe.run()
                deg.append(probe["fcs/elevator-pos-deg"])
    finally:
        del probe
    return _PROBE.copy(), np.array(deg)


class JSBSimFlightModel:
    """A JSBSim aircraft trimmed at ``spec``'s operating point; a ``FlightModel`` in absolute degrees."""

    state_names: tuple[str, ...] = ("alpha_deg", "q_deg_s", "theta_deg", "airspeed_m_s")
    unit = "deg"
    n_faults = 1
    n_wind = 0  # JSBSim makes its own weather (--turbulence)
    rate_limit: float | None = None

    def __init__(self, spec: AircraftSpec) -> None:
        jsbsim = _import_jsbsim()
        self.spec = spec
        self.name = spec.name
        self.h = float(spec.h)
        self.dt = step_size(self.h, spec.dt)
        spec = AircraftSpec(**{**spec.__dict__, "dt": self.dt})
        self.fdm = _load(jsbsim, spec)
        self.version = jsbsim.__version__
        failure = _jsbsim_trim(jsbsim, self.fdm, spec)
        commands, deflections = _elevator_map(jsbsim, spec, trimmed=not failure)
        self.trimmed_by = "JSBSim's trim"
        if failure:  # flown from a fresh instance: a failed trim leaves its engines in no state to fly
            self.fdm = _load(jsbsim, spec)
            xml = _aircraft_xml(spec, Path(jsbsim.get_default_root_dir()))
            _fly_to_trim(self.fdm, spec, commands, deflections, stall_alpha(self.fdm, xml)[0], failure)
            self.trimmed_by = "flying it on the autopilot"
        self.trim_deflection = float(self.fdm["fcs/elevator-pos-deg"])
        total = float(self.fdm["fcs/elevator-cmd-norm"] + self.fdm["fcs/pitch-trim-cmd-norm"])
        self._deg, self._cmd = self._inverse(commands, deflections, total)
        self.travel: tuple[float | None, float | None] = (float(self._deg[0]), float(self._deg[-1]))
        # the pitch trim moves into the command: the surface stays where the trim put it
        self.fdm["fcs/pitch-trim-cmd-norm"] = 0.0
        self.fdm["fcs/elevator-cmd-norm"] = total
        self._command = total
        g = self.fdm.get_property_value
        self.trim = {
            "alpha_deg": g("aero/alpha-deg"),
            "theta_deg": g("attitude/theta-deg"),
            "elevator_deg": self.trim_deflection,
            "throttle": g("fcs/throttle-cmd-norm"),
            "airspeed_kt": g("velocities/vc-kts"),
            "altitude_ft": g("position/h-sl-ft"),
        }
        self._set_turbulence(spec.turbulence)
        self.t = 0.0
        self.n = 0  # JSBSim steps taken
        self.surface = self.trim_deflection  # the deflection last put on the surface (faults included)
        # a mission: the on-board autopilot flies, the servo adds the compensation from outside (``fly``)
        self.autopilot: Autopilot | None = None
        self.timeline: Timeline | None = None
        self.servo = self.trim_deflection  # the servo's position: autopilot + compensation, clipped (or stuck)
        self.servo_command = self.trim_deflection  # the same before a stuck surface held it
        self._own: float | None = None  # the autopilot's elevator for the step under way (deg); None: not yet
        self.compensation = 0.0  # the compensation in force (deg), set by the servo when a command acts
        self.stall_alpha_deg = DEFAULT_STALL_ALPHA_DEG
        if spec.mission is not None:
            self._engage(spec, spec.mission, Path(jsbsim.get_default_root_dir()))

    def _engage(self, spec: AircraftSpec, mission: Mission, bundled_root: Path) -> None:
        """Hand the trimmed aircraft to the autopilot, at JSBSim's trim commands."""
        from sim_vehicle.autopilot import Autopilot, Trim

        fdm = self.fdm
        self.stall_alpha_deg, source = stall_alpha(fdm, _aircraft_xml(spec, bundled_root))
        engines = max(1, int(fdm.get_propulsion().get_num_engines()))
        trim = Trim(
            elevator_deg=self.trim_deflection,
            aileron=fdm["fcs/aileron-cmd-norm"],
            rudder=fdm["fcs/rudder-cmd-norm"],
            throttle=fdm["fcs/throttle-cmd-norm"],
            theta_deg=fdm["attitude/theta-deg"],
            airspeed_kt=fdm["velocities/vc-kts"],
            altitude_ft=fdm["position/h-sl-ft"],
            qbar_psf=fdm["aero/qbar-psf"],
        )
        self.autopilot = Autopilot(
            trim,
            (float(self._deg[0]), float(self._deg[-1])),
            self.dt,
            self.stall_alpha_deg,
            throttles=tuple("fcs/throttle-cmd-norm" + (f"[{i}]" if i else "") for i in range(engines)),
        )
        self.timeline = mission.timeline(self.h, spec.seed)
        log.info(
            "mission %s on %s: stall alpha %.1f deg (%s), %d engine(s)",
            mission,
            self.name,
            self.stall_alpha_deg,
            source,
            engines,
        )

    @property
    def piloted(self) -> bool:
        """Flown by its own autopilot (a mission): the servo drives it through ``fly``, not ``step``."""
        return self.autopilot is not None

    def _inverse(self, commands: np.ndarray, deflections: np.ndarray, total: float) -> tuple[np.ndarray, np.ndarray]:
        """The probed map as (deflection, command), increasing, checked to be a usable static map."""
        what = f"--aircraft {self.name}"
        at_trim = float(np.interp(total, commands, deflections))  # commands increase: -1 ... 1
        if np.all(np.diff(deflections) <= 0):  # a surface that deflects negative for a positive command
            commands, deflections = commands[::-1], deflections[::-1]
        if not np.all(np.diff(deflections) >= -1e-9) or deflections[-1] - deflections[0] < 1.0:
            raise UserError(
                f"{what}: its elevator is not a static, monotone function of fcs/elevator-cmd-norm "
                "(a fly-by-wire pitch channel?); only directly linked elevators are supported"
            )
        if abs(at_trim - self.trim_deflection) > 0.05:
            raise UserError(
                f"{what}: its elevator map gives {at_trim:.3f} deg at the trim command, JSBSim's trim "
                f"{self.trim_deflection:.3f} deg (a pitch channel with feedback?); not supported"
            )
        deg, first = np.unique(deflections, return_index=True)
        return deg, commands[first]

    def _set_turbulence(self, level: str) -> None:
        setting = TURBULENCE_INTENSITY[level]
        if setting is None:
            self.fdm["atmosphere/turb-type"] = 0
            return
        windspeed_fps, severity = setting
        self.fdm["atmosphere/turb-type"] = MILSPEC
        self.fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = windspeed_fps
        self.fdm["atmosphere/turbulence/milspec/severity"] = severity

    # -- FlightModel -------------------------------------------------------------------------------
    def step(
        self, T: float, deflection: float, rate: float, f: Sequence[float] | np.ndarray, d: Sequence[float] | np.ndarray
    ) -> None:
        if self.autopilot is not None:
            raise RuntimeError("an aircraft flying a mission is flown through fly(), by its autopilot")
        t_end = self.t + T
        n_end = int(math.floor(t_end / self.dt + 0.5))
        bias = float(f[0]) if len(f) else 0.0
        fdm = self.fdm
        while self.n < n_end:
            surface = deflection + bias
            if rate:
                surface += rate * max(0.0, self.n * self.dt - self.t)
            if surface != self.surface:
                self._put(surface)
            if not fdm.run():
                raise FlightModelError(f"JSBSim stopped flying {self.name} at t = {self.n * self.dt:.3f} s")
            self.n += 1
        self.t = t_end

    def fly(
        self,
        T: float,
        compensation: float,
        effectiveness: float,
        stuck_at: float | None,
        f: Sequence[float] | np.ndarray,
    ) -> None:
        """Fly ``T`` seconds of the mission on the autopilot, with this compensation and these surface faults.

        At every JSBSim step: the segment flown now and its PRBS level; the autopilot's step (aileron, rudder
        and throttle written, its elevator returned); the servo's position, the autopilot's elevator plus
        ``compensation``, clipped to the travel (or ``stuck_at`` while the surface is stuck); the surface,
        ``effectiveness`` x that position + the additive fault ``f[0]``. A segment the aircraft cannot fly (a
        stall, the throttle held at a stop) raises ``FlightModelError`` naming it.
        """
        pilot, timeline = self.autopilot, self.timeline
        if pilot is None or timeline is None:
            raise RuntimeError("fly() flies a mission: this aircraft has none")
        t_end = self.t + T
        n_end = int(math.floor(t_end / self.dt + 0.5))
        bias = float(f[0]) if len(f) else 0.0
        self.compensation = float(compensation)
        fdm = self.fdm
        if self._own is None:
            self._decide()
        self._apply(effectiveness, stuck_at, bias)  # this call's compensation and faults, from its first step
        while self.n < n_end:
            if not fdm.run():
                raise FlightModelError(f"JSBSim stopped flying {self.name} at t = {self.n * self.dt:.3f} s")
            self.n += 1
            self._decide()
            self._apply(effectiveness, stuck_at, bias)
        self.t = t_end

    def _decide(self) -> None:
        """The autopilot's decision for the step that starts now (``n dt``), from the state JSBSim is in now.

        Why decided at the end of the previous step and not at the start of the next: a sampling instant k h is a
        step boundary, and the sample taken there reports the deflection the vehicle applies from that instant,
        its own controller's u(k), as the observe-only contract says. Decided one step later, the report carried
        the deflection of the step before the instant: every PRBS switch then reached the monitor one sample late
        and read as a fault the size of the switch (2 deg on c172p).
        """
        pilot, timeline = self.autopilot, self.timeline
        assert pilot is not None and timeline is not None  # fly() checked
        t = self.n * self.dt
        segment, excitation = timeline.at(t)
        self._own = pilot.step(
            self.fdm,
            segment.targets,
            excitation,
            hold=segment.excite is not None,
            throttle_excitation=timeline.throttle_at(t) / 100.0,
        )
        if pilot.trouble is not None:
            what, why = pilot.trouble
            raise FlightModelError(f"{self.name}: {what} in segment '{segment.name}' at t = {t:.1f} s: {why}")

    def _apply(self, effectiveness: float, stuck_at: float | None, bias: float) -> None:
        """The servo (the autopilot's elevator plus the compensation, within the travel, or stuck) and the surface."""
        assert self._own is not None
        low, high = float(self._deg[0]), float(self._deg[-1])
        self.servo_command = min(max(self._own + self.compensation, low), high)
        self.servo = self.servo_command if stuck_at is None else stuck_at
        surface = effectiveness * self.servo + bias
        if surface != self.surface:
            self._put(surface)

    def _put(self, surface: float) -> None:
        self.surface = surface
        command = float(np.interp(surface, self._deg, self._cmd))  # clamps to the travel
        if command != self._command:
            self._command = command
            self.fdm["fcs/elevator-cmd-norm"] = command

    def state(self) -> list[float]:
        g = self.fdm.get_property_value
        return [
            g("aero/alpha-deg"),
            math.degrees(g("velocities/q-rad_sec")),
            g("attitude/theta-deg"),
            g("velocities/vc-kts") * KT_TO_M_S,
        ]

    def outputs(self) -> Outputs:
        g = self.fdm.get_property_value
        alpha = g("aero/alpha-deg")
        if not math.isfinite(alpha):
            raise FlightModelError(f"{self.name} left JSBSim's envelope at t = {self.t:.3f} s (alpha is {alpha})")
        if g("position/h-agl-ft") <= 0.0:
            raise FlightModelError(f"{self.name} hit the ground at t = {self.t:.3f} s")
        return Outputs(
            alpha_deg=alpha,
            q_deg_s=math.degrees(g("velocities/q-rad_sec")),
            theta_deg=g("attitude/theta-deg"),
            airspeed_m_s=g("velocities/vc-kts") * KT_TO_M_S,
            attitude=(
                g("attitude/phi-rad"),
                g("attitude/psi-rad"),
                g("velocities/p-rad_sec"),
                g("velocities/r-rad_sec"),
            ),
            hud=(
                g("velocities/vg-fps") * FT_TO_M,
                g("attitude/psi-deg") % 360.0,
                int(round(100.0 * g("fcs/throttle-pos-norm"))),
                g("position/h-sl-meters"),
                g("velocities/h-dot-fps") * FT_TO_M,
            ),
            elevator_parts=None if self.autopilot is None else (self.autopilot.elevator_deg, self.compensation),
        )

    def disturbance(self) -> list[float]:
        """The turbulence velocity now, north/east/down in m/s."""
        g = self.fdm.get_property_value
        return [
            g("atmosphere/turb-north-fps") * FT_TO_M,
            g("atmosphere/turb-east-fps") * FT_TO_M,
            g("atmosphere/turb-down-fps") * FT_TO_M,
        ]

    def truth_extras(self) -> dict:
        g = self.fdm.get_property_value
        extras = {
            # a mission decides the surface for the step that starts at the instant (``_decide``): that one acts
            # from now, where JSBSim's own read-back still shows the step before
            "surface": self.surface if self.autopilot is not None else g("fcs/elevator-pos-deg"),
            "trim": self.trim_deflection,
            "altitude_m": g("position/h-sl-meters"),
            "states": list(self.state_names),
        }
        pilot, timeline = self.autopilot, self.timeline
        if pilot is not None and timeline is not None:  # a mission: what it flies and how, in pilots' units
            segment, excitation = timeline.at(self.t)
            extras.update(
                segment=segment.name,
                airspeed_kt=g("velocities/vc-kts"),
                load_factor=g("accelerations/Nz"),  # JSBSim's normal load factor (1 in level flight), not 1/cos
                bank_deg=g("attitude/phi-deg"),
                heading_deg=g("attitude/psi-deg"),
                altitude_ft=g("position/h-sl-ft"),
                climb_fpm=60.0 * g("velocities/h-dot-fps"),
                throttle=pilot.throttle,
                autopilot_elevator=pilot.elevator_deg,
                compensation=self.compensation,
                excitation=excitation,
                reference={
                    "airspeed_kt": pilot.airspeed_ref,
                    "altitude_ft": pilot.altitude_ref,
                    "climb_fpm": pilot.climb_ref,
                    "bank_deg": pilot.bank_ref,
                    "pitch_deg": pilot.pitch_cmd_deg,
                },
            )
        return extras

    def close(self) -> None:
        self.fdm = None
