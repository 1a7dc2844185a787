"""The identification pipeline: a flight log in, a plant file out (``fault-monitor identify``'s work).

Why a module of its own: the ``identify`` command and the aircraft demo (``monitor.demo.aircraft``, which
identifies the plants it then designs for) both run it, and the benchmarks time it. As part of the command it made
a library package import a command; here it sits below both, and the command only parses, calls ``identify_log``
and prints.

The maths is ``monitor.model.identification``, the plant file's text ``monitor.model.plant_toml``. This module
reads the log and writes the plant file. The log is read by the link layer ``analyse`` reads it with
(``read_tlog`` -> ``FrameParser`` -> the dialect's layouts -> the signal map -> ``SampleAssembler``, observe-only:
a sample needs its actuator report); only the estimator step of ``analyse`` is left out, since there is no plant
yet to estimate with.

The signal map is data (``IDENTIFY_SIGNALS_TOML``, or ``--signals FILE``); ``VFR_HUD.airspeed`` has no time
field and is a latest value of the signal map (sample and hold, ``monitor/link/assembly.py``).

Errors name the command's options (``--sysid``, ``--h``, ...): an ``IdentifyRequest`` is those options as data.
"""

from __future__ import annotations

import dataclasses
import math
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from monitor.files import write_text_atomically
from monitor.link.flight_log import FlightLog, log_spacing, read_flight
from monitor.link.signals import contract_signals_toml
from monitor.wire import TURBULENCE_LEVELS

__all__ = [
    "DEFAULT_ACTUATOR_LIMIT",
    "IDENTIFY_SIGNALS_TOML",
    "TAU_MAX_FRACTION",
    "AirMeasured",
    "IdentifiedLog",
    "IdentifyRequest",
    "identify_log",
    "map_for",
]

KNOWN_INPUT_SIGNALS = ("roll", "r")  # recorded by the plant's map if the identify map measures them
# the flight condition (``[signals] condition``): recorded, and averaged over the identified stretch, when the map
# measures them and they are not states: what an envelope is scheduled on (airspeed, bank) and the known inputs read
CONDITION_SIGNALS = ("airspeed", *KNOWN_INPUT_SIGNALS, "throttle")
# identify's default map for an aircraft's telemetry: the longitudinal states, the elevator and what the turn's
# known inputs need, built from the sample's one definition (monitor.wire.telemetry) as the live default map is
# recorded with the plant's map, neither state nor condition: the compensation in force that a vehicle flying
# its own autopilot reports (run --compensate checks with it that its compensations act; docs/missions.md)
RECORDED_SIGNALS = ("compensation",)
IDENTIFY_SIGNALS_TOML = contract_signals_toml(
    ["alpha", "q", "theta", "airspeed", "elevator", *KNOWN_INPUT_SIGNALS, "throttle", *RECORDED_SIGNALS],
    ranges=False,
)

DEFAULT_ACTUATOR_LIMIT = 25.0
TAU_MAX_FRACTION = 0.46  # of h: the paper's interval [0, 0.4612 h]
_LONG_LOG_RECORDS = 20_000  # a log this long gets progress lines on stderr (a 5-min 20 Hz log has ~24,000)


# --- the signal map -------------------------------------------------------------------------------------------
def _signals_table(path: str | None) -> tuple[dict[str, Any], str]:
    from monitor.errors import UserError

    if path is None:
        return tomllib.loads(IDENTIFY_SIGNALS_TOML)["signals"], "identify's default signal map"
    try:
        raw = tomllib.loads(Path(path).read_text("utf-8"))
    except FileNotFoundError:
        raise UserError(f"{path}: signal map file not found") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"{path}: cannot read signal map: {exc}") from None
    if not isinstance(raw.get("signals"), dict):
        raise UserError(f"{path}: no [signals] table")
    return raw["signals"], str(path)


def map_for(table: dict[str, Any], source: str, states: tuple[str, ...], layouts=None, known: tuple[str, ...] = ()):
    """``(SignalMap, written)``: the project's signal map of ``states`` and the actuator, and the ``[signals]``
    table for the plant file (without its operating point, which the identification adds); ``known``: the known
    inputs, which the map must measure too."""
    from monitor.errors import UserError
    from monitor.link.signals import parse_signals

    measured = table.get("measured")
    if not isinstance(measured, dict):
        raise UserError(f"{source}: [signals] needs a [signals.measured] table")
    actuator = table.get("actuator", ["elevator"])
    actuator = [actuator] if isinstance(actuator, str) else actuator
    if not isinstance(actuator, list) or len(actuator) != 1 or not isinstance(actuator[0], str):
        raise UserError(f"{source}: [signals] 'actuator' must name the one elevator signal")
    for name in known:
        if name in (*states, actuator[0]):
            raise UserError(
                f"--known-input {name}: it is a state or the actuator of the model, not an input besides them"
            )
    missing = [s for s in (*states, actuator[0], *known) if s not in measured]
    if missing:
        raise UserError(
            f"{source}: [signals.measured] has no '{missing[0]}' (identify needs "
            f"{', '.join((*states, actuator[0], *known))})"
        )
    written: dict[str, Any] = {
        "instant": table.get("instant", "AOA_SSA"),
        "outputs": list(states),
        "actuator": list(actuator),
        # airspeed, roll and r (recorded, not outputs) when the map has them: the flight condition
        "measured": {
            s: measured[s]
            for s in dict.fromkeys((*states, actuator[0], *CONDITION_SIGNALS, *RECORDED_SIGNALS))
            if s in measured
        },
        "command": table.get("command", tomllib.loads(IDENTIFY_SIGNALS_TOML)["signals"]["command"]),
    }
    if layouts is not None:
        return parse_signals(written, source, len(states), 1, layouts), written
    return parse_signals(written, source, len(states), 1), written


def _missing_signals(flight: FlightLog, sysid: int, smap, states: tuple[str, ...], model: str) -> str | None:
    """A one-line reason when a signal identify needs never appears for ``sysid`` (None when all are there): the
    missing signals, and which messages of the log could carry them (``monitor.link.log_inventory``)."""
    from monitor.link.log_inventory import explain_missing, field_ref

    names = (*states, *smap.actuator)
    line = explain_missing(flight.inventory, smap, names, sysid)
    if line is None:
        samples = flight.samples.get(sysid, [])
        never = [n for n in states if samples and all(not math.isfinite(v.get(n, math.nan)) for _k, v in samples)]
        if not never:
            return None
        line = (
            "missing signals: "
            + ", ".join(f"{n} ({field_ref(smap.measured[n])})" for n in never)
            + f": never a finite value from sysid {sysid}"
        )
        absent = never
    else:
        absent = [n for n in names if smap.measured[n].message not in flight.inventory.names(sysid)]
    if model == "longitudinal" and absent and set(absent) <= {"theta", "airspeed"}:
        line += "; --model short-period needs only alpha and q"
    return line


DEFAULT_KNOWN_INPUT_LAG = 1.0  # s: a light aircraft's engine and propeller (--known-input-lag)
# --known-input-lag auto: the lags tried (s): an engine's thrust follows its lever within a few seconds
KNOWN_INPUT_LAGS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)


# --- the pipeline ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class IdentifyRequest:
    """What to identify from which log, and where the plant file goes (the command's options, as data)."""

    log: str
    out: str
    model: str = "longitudinal"
    h: float | None = None
    tau_max: float | None = None
    tau_min: float = 0.0
    turbulence: str | None = None
    air_only: str | None = None  # a plant file whose model is kept: only its [disturbance] is measured from the log
    actuator_limit: float = DEFAULT_ACTUATOR_LIMIT
    signals: str | None = None
    sysid: int | None = None
    name: str | None = None
    # (start, end) in seconds from the vehicle's first sample in the log: one leg of a longer flight (a mission's
    # identification leg at one airspeed); None: the whole log
    window: tuple[float, float] | None = None
    # measured signals identified as inputs besides the elevator (throttle), written as [known_inputs.linear]
    known_inputs: tuple[str, ...] = ()
    # their first-order lag in seconds ([known_inputs.lag]); None: picked from KNOWN_INPUT_LAGS by the held-out fit
    known_input_lag: float | None = DEFAULT_KNOWN_INPUT_LAG

    @property
    def plant_name(self) -> str:
        """The plant's name: ``name``, or the output file's stem."""
        return self.name or Path(self.out).stem


@dataclass
class IdentifiedLog:
    """A plant file written from a log: the identification, and what was read to get it."""

    request: IdentifyRequest
    result: Any  # monitor.model.identification.Identification
    sysid: int
    tau_max: float
    units: tuple[str, ...]
    flight: FlightLog
    seconds: float

    @property
    def plant_path(self) -> Path:
        """The plant file written."""
        return Path(self.request.out)

    def report(self) -> dict[str, Any]:
        """``--json``'s document."""
        r, f = self.request, self.flight
        return {
            "source_log": str(r.log),
            "sysid": self.sysid,
            "model": r.model,
            "out": str(r.out),
            "name": r.plant_name,
            "tau_min": r.tau_min,
            "tau_max": self.tau_max,
            "actuator_limit": r.actuator_limit,
            **self.result.report(),
            "log": {
                "records": f.records,
                "skipped_bytes": f.skipped_bytes,
                "truncated": f.truncated,
                "seconds": round(self.seconds, 3),
                **f.counters,
                "inventory": f.inventory.as_dict(),
            },
        }


def _within(rows: Rows, window: tuple[float, float], h_read: float, log: str, sysid: int) -> Rows:
    """The samples of ``rows`` from ``start`` to ``end`` seconds after the vehicle's first one (a leg of a flight).

    Why seconds from the first sample and not the log's clock: a telemetry log's instants are the vehicle's
    boot-relative stamps, which a user reads off a plot of the flight as "the leg from 300 s to 360 s".
    """
    from monitor.errors import UserError

    start, end = window
    k0 = rows[0][0]
    kept = [r for r in rows if start <= (r[0] - k0) * h_read < end]
    span = (rows[-1][0] - k0) * h_read
    if not kept:
        raise UserError(
            f"{log}: --window {start:g}:{end:g} s holds no sample of sysid {sysid} (its samples span 0-{span:.1f} s)"
        )
    return kept


def _checked(req: IdentifyRequest) -> None:
    from monitor.errors import UserError

    if not Path(req.log).is_file():
        raise UserError(f"{req.log}: no such log file")
    if req.sysid is not None and not 1 <= req.sysid <= 255:
        raise UserError(f"--sysid must be a MAVLink system id 1-255, got {req.sysid}")
    if req.h is not None and not (math.isfinite(req.h) and req.h > 0):
        raise UserError(f"--h must be a positive number of seconds, got {req.h}")
    if not (math.isfinite(req.actuator_limit) and req.actuator_limit > 0):
        raise UserError(f"--actuator-limit must be a positive number of degrees, got {req.actuator_limit}")
    if req.turbulence is not None and req.turbulence not in TURBULENCE_LEVELS:
        raise UserError(f"--turbulence must be one of {', '.join(TURBULENCE_LEVELS)}, got {req.turbulence!r}")
    if req.window is not None:
        start, end = req.window
        if not (math.isfinite(start) and math.isfinite(end) and 0 <= start < end):
            raise UserError(f"--window START:END needs 0 <= START < END seconds, got {start:g}:{end:g}")


def _periods(req: IdentifyRequest, smap, dlog=None) -> tuple[float, int, float]:
    """``(h_read, ratio, tau_max)``: the log's own spacing, the decimation to the plant's h, and the delay bound.

    The bounds are checked by the plant's own rules when the file is read back (``0 <= tau_min <= tau_max``,
    at most a few whole samples apart)."""
    from monitor.errors import UserError

    spacing = log_spacing(req.log, smap.instant, req.sysid, dataflash=dlog)
    h_read = spacing or req.h or 0.05
    ratio = 1
    if req.h is not None and spacing is not None:
        ratio = int(round(req.h / spacing))
        if ratio < 1 or abs(req.h - ratio * spacing) > 1e-6 * req.h:
            raise UserError(f"--h {req.h:g} s must be a whole multiple of the log's sample spacing {spacing:g} s")
    h = h_read * ratio
    tau_max = req.tau_max if req.tau_max is not None else max(round(TAU_MAX_FRACTION * h, 9), req.tau_min)
    if not (math.isfinite(req.tau_min) and math.isfinite(tau_max) and 0 <= req.tau_min <= tau_max):
        raise UserError(f"--tau-min/--tau-max must satisfy 0 <= tau_min <= tau_max, got {req.tau_min}, {tau_max}")
    return h_read, ratio, tau_max


def _vehicle(req: IdentifyRequest, flight: FlightLog, smap, states: tuple[str, ...]) -> int:
    """The one system id to identify: the one asked for, or the only one with samples (else a one-line error)."""
    from monitor.errors import UserError
    from monitor.link.log_inventory import explain_missing

    with_samples = sorted(s for s, rows in flight.samples.items() if rows)
    if req.sysid is None and len(with_samples) > 1:
        raise UserError(
            f"{req.log}: the log holds samples of vehicles {', '.join(map(str, with_samples))}: choose one with --sysid"
        )
    candidates = [req.sysid] if req.sysid is not None else (with_samples or sorted(flight.seen) or [])
    if not candidates:
        why = explain_missing(flight.inventory, smap, (*states, *smap.actuator)) or "no message the signal map reads"
        raise UserError(f"{req.log} ({flight.records} records): {why}")
    return candidates[0]


def identify_log(req: IdentifyRequest, say: Callable[[str], None] = lambda _text: None) -> IdentifiedLog:
    """Read ``req.log`` (a tlog, or a DataFlash log: ``.bin``/``.log``), identify the model, write ``req.out``
    (loadable as it is); UserError names what is wrong."""
    from monitor.link.onboard_log import open_onboard_log

    _checked(req)

    dlog = open_onboard_log(req.log)  # an on-board log (DataFlash or ULog), None for a tlog
    try:
        return _identify(req, say, dlog)
    finally:
        if dlog is not None:
            dlog.close()


def _identify(req: IdentifyRequest, say: Callable[[str], None], dlog) -> IdentifiedLog:
    """``identify_log`` once the log is open (``dlog``: the DataFlash log, None for a tlog)."""
    import numpy as np

    from monitor.errors import UserError
    from monitor.model.identification import MODELS, FlightData
    from monitor.model.plant import parse_plant
    from monitor.model.plant_toml import plant_toml

    states = MODELS[req.model]
    kept = None
    envelope = None
    if req.air_only is not None:  # the plant's own map reads the log, its model explains it
        from monitor.model.envelope import is_envelope, load_envelope
        from monitor.model.plant import load_plant

        if is_envelope(req.air_only):  # the points share one map: the first reads the log
            envelope = load_envelope(req.air_only)
            kept = envelope.first.physical
        else:
            kept = load_plant(req.air_only).physical
        if kept.continuous is None or not kept.signals:
            raise UserError(
                f"--air-only {req.air_only}: needs a continuous plant with a [signals] table (one written by identify)"
            )
        states = tuple(kept.signals.get("outputs", ()))
        req = dataclasses.replace(req, signals=req.air_only, h=kept.h)
    if dlog is not None and req.signals is None:
        hints = "; ".join(
            dlog.inventory.providers(
                ("angle of attack", "body rates (gyro)", "attitude", "airspeed", "actuator output")
            )
        )
        raise UserError(f"{req.log}: {dlog.layouts.no_map()}; the log has {hints}")
    if kept is not None and kept.signals:  # the kept model's own map (an envelope's is in its points)
        table, source = kept.signals, str(req.air_only)
    else:
        table, source = _signals_table(req.signals)
    smap, written = map_for(table, source, states, dlog.layouts if dlog is not None else None, req.known_inputs)
    h_read, ratio, tau_max = _periods(req, smap, dlog)
    h = h_read * ratio

    started = time.perf_counter()
    flight = read_flight(
        req.log,
        smap,
        h_read,
        req.sysid,
        progress=lambda f, n: say(f"{f:.0%} of {req.log}, {n} samples"),
        dataflash=dlog,
    )
    sysid = _vehicle(req, flight, smap, states)
    reason = _missing_signals(flight, sysid, smap, states, req.model)
    if reason:
        raise UserError(reason)
    rows = flight.samples.get(sysid, [])
    if not rows:
        from monitor.link.log_inventory import why_no_samples

        raise UserError(
            f"{req.log}: no sample of sysid {sysid} could be assembled: "
            + why_no_samples(flight.inventory, smap, (*states, *smap.actuator), sysid, h_read)
        )
    if req.window is not None:
        rows = _within(rows, req.window, h_read, req.log, sysid)
    actuator = written["actuator"][0]
    if ratio > 1:
        rows = _decimate(rows, ratio, actuator)
    k = np.array([r[0] for r in rows], dtype=np.int64)
    X = np.array([[v.get(s, math.nan) for s in states] for _k, v in rows], dtype=float).reshape(len(rows), len(states))
    inputs = (actuator, *req.known_inputs)
    U = np.array([[v.get(s, math.nan) for s in inputs] for _k, v in rows], dtype=float).reshape(len(rows), len(inputs))
    for j, name in enumerate(req.known_inputs, start=1):
        moved = np.nanmax(U[:, j]) - np.nanmin(U[:, j]) if np.isfinite(U[:, j]).any() else 0.0
        if not moved > 0.0:
            raise UserError(
                f"--known-input {name}: it does not move over the log (spread {moved:g}): its effect cannot be "
                "identified (a mission leg with excite_throttle moves the throttle)"
            )
    units = tuple(smap.measured[s].unit for s in states)  # the parsed map's: a derived signal's default unit too
    if kept is not None:
        if envelope is not None:
            return _measure_envelope_air(req, envelope, rows, k, X, U, states, sysid)
        return _measure_air(req, kept, k, X, U, states, sysid)
    if flight.records >= _LONG_LOG_RECORDS:
        say(
            f"{len(rows)} samples of sysid {sysid} read in {time.perf_counter() - started:.1f} s; fitting and "
            "validating"
        )
    result, lags = _identify_with_lags(
        FlightData(h=h, k=k, states=X, inputs=U, state_names=states, input_names=inputs, state_units=units),
        say,
        KNOWN_INPUT_LAGS if req.known_input_lag is None else (req.known_input_lag,),
    )
    seconds = time.perf_counter() - started

    out = Path(req.out)
    name = req.plant_name
    custom_limit = req.actuator_limit != DEFAULT_ACTUATOR_LIMIT
    limit_source = (
        "given with --actuator-limit"
        if custom_limit
        else "a safe default: a log shows the deflections flown, not the stops; check them"
    )
    header = [
        f"Identified by fault-monitor identify from {Path(req.log).name} (sysid {sysid}), model {req.model}.",
        "States are deviations from [signals] operating_point, in "
        + ", ".join(f"{s_} {u}".rstrip() for s_, u in zip(states, units, strict=True))
        + f"; input: {actuator} deg.",
        "D_cf = B_c (an elevator fault); D_cd = the alpha column of A_c (a vertical gust as an alpha "
        "disturbance, deg).",
    ]
    description = (
        f"{req.model} model identified from {Path(req.log).name}: {result.samples} samples at "
        f"h = {h:g} s, held-out fit " + ", ".join(f"{s} {f:.1f} %" for s, f in result.fit_validation.items())
    )
    text = plant_toml(
        result,
        name=name,
        description=description,
        tau_min=req.tau_min,
        tau_max=tau_max,
        turbulence=req.turbulence,
        actuator_limit=req.actuator_limit,
        actuator_limit_source=limit_source,
        signals=written,
        source_log=str(req.log),
        model=req.model,
        header=header,
        condition=_condition(rows, written),
        known_lags=lags,
    )
    parse_plant(text, source=str(out))  # the file must load as it is: a plant the chain takes
    try:
        write_text_atomically(out, text)
    except OSError as exc:
        raise UserError(f"{out}: cannot write the plant file: {exc.strerror or exc}") from None
    return IdentifiedLog(req, result, sysid, tau_max, units, flight, seconds)


def _identify_with_lags(data, say: Callable[[str], None], lags: tuple[float, ...] = KNOWN_INPUT_LAGS):
    """``(identification, {known input: lag s})``: without known inputs, the plain fit; with them, the fit at each
    of ``lags`` (every known input through one first-order lag, ``monitor.model.known_inputs``), and the one with
    the best held-out fit (the mean over the states) kept. Why a lag: the throttle's effect on the pitching
    moment (thrust, and the propeller's wash over the tail) follows the lever in about a second; an instant column
    fitted to a lagged effect comes out too small (c172p at 65 kt: a third of the steady effect). Why the default
    is one given lag and not the grid: a longer lag with a larger column fits a leg about as well, and the grid's
    pick moved between 1.5 and 3 s from one identification flight of c172p to the next, its column by 2x."""
    import dataclasses

    import numpy as np

    from monitor.model.identification import identify
    from monitor.model.known_inputs import lagged

    if len(data.input_names) < 2:
        return identify(data), {}
    best = None
    scores = []
    U = np.asarray(data.inputs, dtype=float)
    k = np.asarray(data.k, dtype=np.int64)
    for lag in lags:
        shifted = U.copy()
        for j in range(1, U.shape[1]):
            shifted[:, j] = lagged(U[:, j], k, lag, data.h)
        result = identify(dataclasses.replace(data, inputs=shifted))
        score = float(np.mean(list(result.fit_validation.values())))
        scores.append(f"{lag:g} s {score:.1f} %")
        if best is None or score > best[0]:
            best = (score, lag, result)
    assert best is not None
    _score, lag, result = best
    if len(lags) > 1:
        say(f"known input lag {lag:g} s kept (held-out fit, mean of the states: {', '.join(scores)})")
    return result, {name: lag for name in data.input_names[1:]}


def _condition(rows: Rows, written: dict[str, Any]) -> dict[str, float]:
    """The flight condition of the identified stretch (``[signals] condition``): the mean of each measured signal
    that is not a state or the actuator (roll, r) over the rows that have it. A leg flown in a turn says so, and
    ``fault-monitor envelope --schedule roll`` can place it."""
    import numpy as np

    condition: dict[str, float] = {}
    for name in CONDITION_SIGNALS:
        if name in written["measured"] and name not in written["outputs"]:
            values = [v[name] for _k, v in rows if name in v and math.isfinite(v[name])]
            if values:
                condition[name] = float(np.mean(values))
    return condition


def _gust(req: IdentifyRequest, kept, k, X, U, states) -> dict[str, float]:
    """The gust this log met, seen through ``kept``'s model about its operating point (``gust_from_residual``)."""
    import numpy as np

    from monitor.errors import UserError
    from monitor.link.signals import parse_signals
    from monitor.model.identification import gust_from_residual

    smap = parse_signals(kept.signals, kept.source, len(states), kept.m)  # the kept plant's operating point
    gust = gust_from_residual(
        k, X - np.array(smap.y0), U - np.array(smap.u0), kept.A, kept.B0 + kept.B1, states, kept.h
    )
    if gust is None:
        raise UserError(f"{req.log}: too few consecutive samples (or no alpha) to measure the gust")
    return gust


STEADY_SHARE = 0.25  # --air-only ENVELOPE: the most a schedule variable may move over the log, of the points' span


def _measure_envelope_air(req: IdentifyRequest, envelope, rows: Rows, k, X, U, states, sysid: int):
    """``--air-only ENVELOPE``: the gust measured with the point nearest where the log was flown (the means of
    the schedule's variables over it), written into every point scaled by its airspeed (``envelope_with_air``)."""
    import numpy as np

    from monitor.errors import UserError
    from monitor.model.envelope import envelope_with_air
    from monitor.model.flight_condition import schedule_value

    where: dict[str, float] = {}
    for name in envelope.schedule:
        values = np.array([schedule_value(name, v) for _k, v in rows], dtype=float)
        if not np.isfinite(values).any():
            raise UserError(
                f"{req.log}: no value of the schedule's {name!r} in the samples: the log must measure what the "
                "envelope is scheduled on, to know which point's model explains it"
            )
        where[name] = float(np.nanmean(values))
        low, high = np.nanpercentile(values, [5, 95])
        span = float(np.ptp(envelope.at_matrix[:, envelope.schedule.index(name)]))
        if span > 0 and high - low > STEADY_SHARE * span:
            raise UserError(
                f"{req.log}: the flight moves {name} from {low:.4g} to {high:.4g} (5th to 95th percentile; the "
                f"points span {span:.4g}): the air is measured on a steady stretch, where one point's model explains "
                "the flight: give --window START:END over one (a level leg)"
            )
    point = envelope.nearest(where)
    gust = _gust(req, point.plant.physical, k, X, U, states)
    speeds = [v["airspeed"] for _k, v in rows if math.isfinite(v.get("airspeed", math.nan))]
    text = envelope_with_air(
        envelope,
        gust,
        float(np.mean(speeds)) if speeds else None,
        req.turbulence,
        f"{Path(req.log).name}, sysid {sysid}, with point {point.name}",
    )
    _write_plant_text(Path(req.out), text)
    return AirMeasured(req, sysid, gust, point=point.name, where=where)


def _write_plant_text(out: Path, text: str) -> None:
    from monitor.errors import UserError

    try:
        write_text_atomically(out, text)
    except OSError as exc:
        raise UserError(f"{out}: cannot write the plant file: {exc.strerror or exc}") from None


def _measure_air(req: IdentifyRequest, kept, k, X, U, states, sysid: int):
    """``--air-only``: the kept plant's file, its ``[disturbance]`` measured from this log (``gust_from_residual``)."""
    from monitor.model.plant import parse_plant
    from monitor.model.plant_toml import disturbance_table

    gust = _gust(req, kept, k, X, U, states)
    assert req.air_only is not None  # kept is the --air-only plant
    text = Path(req.air_only).read_text("utf-8")
    kept_lines, skipping = [], False
    for line in text.splitlines():  # every line but the old [disturbance] table's
        if line.strip().startswith("["):
            skipping = line.strip() == "[disturbance]"
        if not skipping:
            kept_lines.append(line)
    table = disturbance_table(gust, req.turbulence, source=f"{Path(req.log).name}, sysid {sysid}, with this model")
    text = "\n".join(kept_lines).rstrip() + "\n\n" + "\n".join(table) + "\n"
    out = Path(req.out)
    parse_plant(text, source=str(out))
    _write_plant_text(out, text)
    return AirMeasured(req, sysid, gust)


@dataclass
class AirMeasured:
    """``--air-only``'s result: the gust measured, and the plant file written with it."""

    request: IdentifyRequest
    sysid: int
    gust: dict[str, float]
    point: str | None = None  # an envelope's: the point whose model measured it
    where: dict[str, float] | None = None  # an envelope's: the schedule's means over the log

    @property
    def summary(self) -> str:
        line = f"gust sigma {self.gust['sigma']:.4g} deg, time constant {self.gust['time_constant']:.3g} s"
        if self.point is not None and self.where is not None:
            place = ", ".join(f"{name} {value:.4g}" for name, value in self.where.items())
            line += f" (with point {self.point}, nearest the flight's mean {place}; every point's scaled by airspeed)"
        return line

    def report(self) -> dict[str, Any]:
        return {
            "source_log": str(self.request.log),
            "sysid": self.sysid,
            "out": str(self.request.out),
            "kept_model": str(self.request.air_only),
            "disturbance": self.gust,
            "turbulence": self.request.turbulence,
            **({"point": self.point, "where": self.where} if self.point is not None else {}),
        }


Rows = list[tuple[int, dict[str, float]]]


def _decimate(rows: Rows, ratio: int, actuator: str) -> Rows:
    """Every ``ratio``-th sample's states, with the elevator averaged over the samples of its new period.

    Why the mean: the model holds u over a period of ``ratio`` log samples; a deflection that switched inside it
    acted for part of it, and the mean is what a held input equivalent to it is to first order.
    """
    buckets: dict[int, list[float]] = {}
    for k, v in rows:
        buckets.setdefault(k // ratio, []).append(v.get(actuator, math.nan))
    out = []
    for k, v in rows:
        if k % ratio == 0:
            u = buckets[k // ratio]
            out.append((k // ratio, {**v, actuator: sum(u) / len(u)}))
    return out
