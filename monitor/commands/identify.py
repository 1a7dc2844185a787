"""``fault-monitor identify FLIGHT.tlog --out PLANT.toml``: a continuous plant from a flight's telemetry log.

The maths is ``monitor.model.identification``. This module reads the log and writes the plant file. The log is
read by the link layer ``analyse`` reads it with (``read_tlog`` -> ``FrameParser`` -> the dialect's layouts ->
the signal map -> ``SampleAssembler``, observe-only: a sample needs its actuator report); only the estimator
step of ``analyse`` is left out, since there is no plant yet to estimate with.

The signal map is data (``IDENTIFY_SIGNALS_TOML``, or ``--signals FILE``); ``VFR_HUD.airspeed`` has no time
field and is a latest value of the signal map (sample and hold, ``monitor/link/assembly.py``).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["IDENTIFY_SIGNALS_TOML", "FlightLog", "log_spacing", "read_flight", "register"]

IDENTIFY_SIGNALS_TOML = """
[signals]
instant = "AOA_SSA"
actuator = ["elevator"]
[signals.measured]
alpha = { field = "AOA_SSA.AOA", unit = "deg" }
q = { field = "ATTITUDE.pitchspeed", scale = 57.29577951308232, unit = "deg/s" }
theta = { field = "ATTITUDE.pitch", scale = 57.29577951308232, unit = "deg" }
airspeed = { field = "VFR_HUD.airspeed", unit = "m/s" }
elevator = { field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }
[signals.command]
message = "SET_ACTUATOR_CONTROL_TARGET"
channels = [1]
full_scale = [30.0]
group = 0
"""

DEFAULT_ACTUATOR_LIMIT = 25.0
TAU_MAX_FRACTION = 0.46  # of h: the paper's interval [0, 0.4612 h]
_PROBE_INSTANTS = 400  # instant messages looked at to find the log's sample spacing
_LONG_LOG_RECORDS = 20_000  # a log this long gets progress lines on stderr (a 5-min 20 Hz log has ~24,000)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "identify", help="identify a continuous plant from a flight log (.tlog) with an elevator manoeuvre",
        description=(
            "Fit x' = A_c x + B_c u (deviations from the operating point) to a telemetry log of a flight with an "
            "elevator manoeuvre (e.g. sim-vehicle run --excite prbs:1:60), every state measured: least squares on "
            "the sampled model, refined by output error (the free run's error), A_c = logm(A_d)/h. The model is "
            "validated by a free run over the last 30 % of the manoeuvre, which it was not fitted on (fit % per "
            "output, NRMSE). Writes a plant file that 'fault-monitor design' takes as it is, with its signal map "
            "and operating point. Exit 2 with one line when the log cannot be identified from (no excitation, "
            "missing signals, too short)."),
        epilog="Example: fault-monitor identify flight.tlog --out c172p.toml && "
               "fault-monitor design --plant c172p.toml --out gains.toml")
    p.add_argument("tlog", metavar="FLIGHT.tlog", help="the telemetry log (MAVProxy / QGroundControl format)")
    p.add_argument("--out", required=True, metavar="PLANT.toml", help="the plant file to write")
    p.add_argument("--model", choices=("short-period", "longitudinal"), default="longitudinal",
                   help="states: short-period = alpha, q; longitudinal = alpha, q, theta, airspeed "
                        "(default: longitudinal)")
    p.add_argument("--h", type=float, metavar="S", help="sampling period of the plant, a whole multiple of the "
                   "log's own sample spacing (default: that spacing, from the AOA_SSA time stamps)")
    p.add_argument("--tau-max", type=float, metavar="S", help="upper bound of the network delay written to the "
                   "plant, 0 <= S < h (default: 0.46 h)")
    p.add_argument("--actuator-limit", type=float, metavar="DEG", default=DEFAULT_ACTUATOR_LIMIT,
                   help="elevator limit about trim written to [actuator] (default: 25.0; a log shows the "
                        "deflections flown, not the aircraft's stops)")
    p.add_argument("--signals", metavar="FILE", help="a [signals] table naming where alpha, q, theta, airspeed "
                   "and the elevator are in the log (default: AOA_SSA.AOA, ATTITUDE.pitchspeed and .pitch, "
                   "VFR_HUD.airspeed, ACTUATOR_OUTPUT_STATUS.actuator[0])")
    p.add_argument("--sysid", type=int, metavar="N", help="the vehicle to identify (needed when the log holds "
                   "several)")
    p.add_argument("--name", help="the plant's name (default: the output file's stem)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=run)


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


def _map_for(table: dict[str, Any], source: str, states: tuple[str, ...]):
    """``(SignalMap, written)``: the project's signal map of ``states`` and the actuator, and the ``[signals]``
    table for the plant file (without its operating point, which the identification adds)."""
    from monitor.errors import UserError
    from monitor.link.signals import parse_signals

    measured = table.get("measured")
    if not isinstance(measured, dict):
        raise UserError(f"{source}: [signals] needs a [signals.measured] table")
    actuator = table.get("actuator", ["elevator"])
    actuator = [actuator] if isinstance(actuator, str) else actuator
    if not isinstance(actuator, list) or len(actuator) != 1 or not isinstance(actuator[0], str):
        raise UserError(f"{source}: [signals] 'actuator' must name the one elevator signal")
    missing = [s for s in (*states, actuator[0]) if s not in measured]
    if missing:
        raise UserError(f"{source}: [signals.measured] has no '{missing[0]}' (identify needs "
                        f"{', '.join((*states, actuator[0]))})")
    written: dict[str, Any] = {"instant": table.get("instant", "AOA_SSA"), "outputs": list(states),
                               "actuator": list(actuator),
                               "measured": {s: measured[s] for s in (*states, actuator[0])},
                               "command": table.get("command",
                                                    tomllib.loads(IDENTIFY_SIGNALS_TOML)["signals"]["command"])}
    return parse_signals(written, source, len(states), 1), written


def _field_of(spec: Any) -> str:
    return str(spec.get("field") if isinstance(spec, dict) else spec)


# --- the log --------------------------------------------------------------------------------------------------
class FlightLog:
    """What ``read_flight`` found: per system id the samples (k, values), and what was seen."""

    def __init__(self) -> None:
        self.samples: dict[int, list[tuple[int, dict[str, float]]]] = {}
        self.seen: dict[int, dict[str, int]] = {}
        self.records = 0
        self.skipped_bytes = 0
        self.truncated = False
        self.counters: dict[str, int] = {}


def log_spacing(path: str, instant: str, sysid: int | None) -> float | None:
    """The median spacing of the instant message's ``time_usec`` over the first few hundred (s), or None."""
    from monitor.link.dialect import layout_by_name
    from monitor.link.frames import FrameCounters, FrameParser
    from monitor.link.tlog import read_tlog

    layout = layout_by_name(instant)
    if layout is None or layout.time_field() is None:
        return None
    pos = layout.position(layout.time_field()[0])
    unit = layout.time_field()[1]
    parser = FrameParser(FrameCounters())
    stamps: list[int] = []
    for _t, frame in read_tlog(path):
        for msgid, sys_, _c, payload in parser.feed(frame):
            if msgid == layout.msgid and (sysid is None or sys_ == sysid):
                stamps.append(int(layout.decode(payload)[pos]) * unit)
        if len(stamps) >= _PROBE_INSTANTS:
            break
    steps = sorted(b - a for a, b in itertools.pairwise(stamps) if b > a)
    if not steps:
        return None
    return steps[len(steps) // 2] / 1e6


def read_flight(path: str, smap, h: float, sysid: int | None = None,
                progress: Callable[[float, int], None] | None = None, progress_every_s: float = 2.0) -> FlightLog:
    """Every sample of every vehicle (only ``sysid``'s if given), assembled as ``analyse`` assembles them."""
    from monitor.link.assembly import SampleAssembler
    from monitor.link.dialect import layout_by_name
    from monitor.link.frames import FrameCounters, FrameParser
    from monitor.link.tlog import TlogStats, read_tlog

    wanted = {}
    for name in {smap.instant, *(s.message for s in smap.measured.values())}:
        layout = layout_by_name(name)
        wanted[layout.msgid] = (layout.name, layout)
    counters = FrameCounters()
    parser = FrameParser(counters)
    stats = TlogStats()
    out = FlightLog()
    assemblers: dict[int, SampleAssembler] = {}
    size = max(os.path.getsize(path), 1)
    position = 0
    start = time.perf_counter()
    next_report = start + progress_every_s

    def keep(sys_: int, ready) -> None:
        out.samples.setdefault(sys_, []).extend((sample.k, sample.values) for sample in ready)

    for t_us, frame in read_tlog(path, stats):
        position += 8 + len(frame)
        for msgid, sys_, _compid, payload in parser.feed(frame):
            entry = wanted.get(msgid)
            if entry is None or (sysid is not None and sys_ != sysid):
                continue
            name, layout = entry
            seen = out.seen.setdefault(sys_, {})
            seen[name] = seen.get(name, 0) + 1
            values = layout.decode(payload)
            asm = assemblers.get(sys_)
            if asm is None:
                asm = assemblers[sys_] = SampleAssembler(smap, h, observe=True)
            if asm.uses(name):
                keep(sys_, asm.add(name, values, None, t_us * 1e-6))
        if progress is not None and stats.records % 4096 == 0 and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + progress_every_s
            progress(position / size, sum(len(v) for v in out.samples.values()))
    for sys_, asm in assemblers.items():
        keep(sys_, asm.flush(math.inf))
    out.records, out.skipped_bytes, out.truncated = stats.records, stats.skipped_bytes, stats.truncated
    totals: dict[str, int] = counters.as_dict()
    for asm in assemblers.values():
        for key, value in asm.counters.as_dict().items():
            totals[key] = totals.get(key, 0) + value
    out.counters = totals
    return out


def _missing_signals(flight: FlightLog, sysid: int, written: dict[str, Any], states: tuple[str, ...],
                     model: str) -> str | None:
    """A one-line reason when a signal identify needs never appears for ``sysid`` (None when all are there)."""
    seen = flight.seen.get(sysid, {})
    measured = written["measured"]
    names = [*states, *written["actuator"]]
    absent = [n for n in names if _field_of(measured[n]).partition(".")[0] not in seen]
    if written["instant"] not in seen and not any(_field_of(measured[n]).startswith(written["instant"] + ".")
                                                  for n in absent):
        absent.insert(0, f"the instant ({written['instant']})")
    if not absent:
        samples = flight.samples.get(sysid, [])
        absent = [n for n in states if samples and all(not math.isfinite(v.get(n, math.nan)) for _k, v in samples)]
    if not absent:
        return None
    what = ", ".join(n if n.startswith("the instant") else f"{n} ({_field_of(measured[n])})" for n in absent)
    messages = sorted({_field_of(measured[n]).partition(".")[0] for n in absent if not n.startswith("the instant")})
    line = f"missing signals: {what}: the log has no {' or '.join(messages) or written['instant']} from sysid {sysid}"
    if model == "longitudinal" and set(absent) <= {"theta", "airspeed"}:
        line += "; --model short-period needs only alpha and q"
    return line


# --- the command ----------------------------------------------------------------------------------------------
def run(args: argparse.Namespace) -> int:
    import numpy as np

    from monitor.errors import UserError
    from monitor.model.identification import MODELS, FlightData, identify, plant_toml
    from monitor.model.plant import parse_plant

    path = args.tlog
    if not Path(path).is_file():
        raise UserError(f"{path}: no such log file")
    if args.sysid is not None and not 1 <= args.sysid <= 255:
        raise UserError(f"--sysid must be a MAVLink system id 1-255, got {args.sysid}")
    if args.h is not None and not (math.isfinite(args.h) and args.h > 0):
        raise UserError(f"--h must be a positive number of seconds, got {args.h}")
    if not (math.isfinite(args.actuator_limit) and args.actuator_limit > 0):
        raise UserError(f"--actuator-limit must be a positive number of degrees, got {args.actuator_limit}")
    states = MODELS[args.model]
    table, source = _signals_table(args.signals)
    smap, written = _map_for(table, source, states)
    say = (lambda text: print(f"identify: {text}", file=sys.stderr, flush=True))

    spacing = log_spacing(path, smap.instant, args.sysid)
    h_read = spacing or args.h or 0.05
    ratio = 1
    if args.h is not None and spacing is not None:
        ratio = int(round(args.h / spacing))
        if ratio < 1 or abs(args.h - ratio * spacing) > 1e-6 * args.h:
            raise UserError(f"--h {args.h:g} s must be a whole multiple of the log's sample spacing {spacing:g} s")
    h = h_read * ratio
    if args.tau_max is not None and not (math.isfinite(args.tau_max) and 0 <= args.tau_max < h):
        raise UserError(f"--tau-max must satisfy 0 <= tau_max < h = {h:g} s, got {args.tau_max}")
    tau_max = args.tau_max if args.tau_max is not None else round(TAU_MAX_FRACTION * h, 9)

    started = time.perf_counter()
    flight = read_flight(path, smap, h_read, args.sysid,
                         progress=lambda f, n: say(f"{f:.0%} of {path}, {n} samples"))
    with_samples = sorted(s for s, rows in flight.samples.items() if rows)
    if args.sysid is None and len(with_samples) > 1:
        raise UserError(f"{path}: the log holds samples of vehicles {', '.join(map(str, with_samples))}: choose one "
                        "with --sysid")
    candidates = [args.sysid] if args.sysid is not None else (with_samples or sorted(flight.seen) or [])
    if not candidates:
        raise UserError(f"missing signals: {path} holds none of the messages the signal map reads "
                        f"({', '.join(sorted({_field_of(v).partition('.')[0] for v in written['measured'].values()}))}"
                        f"; {flight.records} records)")
    sysid = candidates[0]
    reason = _missing_signals(flight, sysid, written, states, args.model)
    if reason:
        raise UserError(reason)
    rows = flight.samples.get(sysid, [])
    actuator = written["actuator"][0]
    if ratio > 1:
        rows = _decimate(rows, ratio, actuator)
    k = np.array([r[0] for r in rows], dtype=np.int64)
    X = np.array([[v.get(s, math.nan) for s in states] for _k, v in rows], dtype=float).reshape(len(rows), len(states))
    U = np.array([[v.get(actuator, math.nan)] for _k, v in rows], dtype=float).reshape(len(rows), 1)
    units = tuple(str(written["measured"][s].get("unit", "")) if isinstance(written["measured"][s], dict) else ""
                  for s in states)
    if flight.records >= _LONG_LOG_RECORDS:
        say(f"{len(rows)} samples of sysid {sysid} read in {time.perf_counter() - started:.1f} s; fitting and "
            "validating")
    result = identify(FlightData(h=h, k=k, states=X, inputs=U, state_names=states, input_names=(actuator,),
                                 state_units=units))
    seconds = time.perf_counter() - started

    out = Path(args.out)
    name = args.name or out.stem
    limit_source = ("given with --actuator-limit" if args.actuator_limit != DEFAULT_ACTUATOR_LIMIT else
                    "a safe default: a log shows the deflections flown, not the stops; check them")
    header = [f"Identified by fault-monitor identify from {Path(path).name} (sysid {sysid}), model {args.model}.",
              "States are deviations from [signals] operating_point, in "
              + ", ".join(f"{s_} {u}".rstrip() for s_, u in zip(states, units)) + f"; input: {actuator} deg.",
              "D_cf = B_c (an elevator fault); D_cd = the alpha column of A_c (a vertical gust as an alpha "
              "disturbance, deg)."]
    description = (f"{args.model} model identified from {Path(path).name}: {result.samples} samples at "
                   f"h = {h:g} s, held-out fit "
                   + ", ".join(f"{s} {f:.1f} %" for s, f in result.fit_validation.items()))
    text = plant_toml(result, name=name, description=description, tau_max=tau_max,
                      actuator_limit=args.actuator_limit, actuator_limit_source=limit_source, signals=written,
                      source_log=str(path), model=args.model, header=header)
    parse_plant(text, source=str(out))  # the file must load as it is: a plant the chain takes
    _write_atomically(out, text)

    if args.json:
        report = {"source_log": str(path), "sysid": sysid, "model": args.model, "out": str(out), "name": name,
                  "tau_max": tau_max, "actuator_limit": args.actuator_limit, **result.report(),
                  "log": {"records": flight.records, "skipped_bytes": flight.skipped_bytes,
                          "truncated": flight.truncated, "seconds": round(seconds, 3), **flight.counters}}
        print(json.dumps(report))
        return 0
    print(_format(result, path, sysid, args.model, units))
    print(f"wrote {out}: tau in [0, {tau_max:g}] s, actuator limit {args.actuator_limit:g} deg "
          f"({'given' if args.actuator_limit != DEFAULT_ACTUATOR_LIMIT else 'default'}); "
          f"{flight.records} log records in {seconds:.2f} s")
    return 0


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


def _format(result, path: str, sysid: int, model: str, units: tuple[str, ...]) -> str:
    ex = result.excitation
    unit_of = dict(zip(result.state_names, units))
    unit_of.update({name: "deg" for name in result.input_names})
    op = ", ".join(f"{name} {value:.4f} {unit_of.get(name, '')}".rstrip() for name, value in
                   result.operating_point.items())
    lines = [
        f"identified {model} model ({', '.join(result.state_names)}) from {path} (sysid {sysid}): "
        f"{result.samples} samples at h = {result.h:g} s",
        f"excitation  {ex['start_s']:.2f} .. {ex['end_s']:.2f} s ({ex['seconds']:.1f} s, elevator spread "
        f"{ex['spread_deg']:.3g} deg); fitted {result.samples_estimation} sample pairs, held out "
        f"{result.validation_span_s[0]:.2f} .. {result.validation_span_s[1]:.2f} s "
        f"({result.samples_validation} samples)",
        f"operating point  {op}",
        f"                 ({result.operating_point_source})",
    ]
    for i, mode in enumerate(result.modes):
        lines.append(("modes       " if i == 0 else "            ") + mode.describe())
    lines.append("fit on held-out data (free run, NRMSE)  " +
                 ", ".join(f"{s} {f:.1f} %" for s, f in result.fit_validation.items()))
    for note in result.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines)


def _write_atomically(path: Path, text: str) -> None:
    from monitor.errors import UserError

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=path.name, dir=path.parent)
    except OSError as exc:
        raise UserError(f"{path}: cannot write the plant file: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise UserError(f"{path}: cannot write the plant file: {exc.strerror or exc}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
