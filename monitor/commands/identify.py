"""``fault-monitor identify FLIGHT.tlog --out PLANT.toml``: a continuous plant from a flight's telemetry log.

Argument parsing and printing only: the pipeline (read the log, identify, write the plant file) is
``monitor.pipelines.identify_log``, the maths ``monitor.model.identification``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from monitor.pipelines.identify_log import (
    DEFAULT_ACTUATOR_LIMIT,
    DEFAULT_KNOWN_INPUT_LAG,
    KNOWN_INPUT_LAGS,
    AirMeasured,
    IdentifyRequest,
    identify_log,
)
from monitor.wire import TURBULENCE_LEVELS

__all__ = ["register"]


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "identify",
        help="identify a continuous plant from a flight log (.tlog, .bin/.log, .ulg) with an elevator manoeuvre",
        description=(
            "Fit x' = A_c x + B_c u (deviations from the operating point) to a telemetry log of a flight with an "
            "elevator manoeuvre (e.g. sim-vehicle run --excite prbs:1:60), every state measured: least squares on "
            "the sampled model, refined by output error (the free run's error), A_c = logm(A_d)/h. The model is "
            "validated by a free run over the last 30 % of the manoeuvre, which it was not fitted on (fit % per "
            "output, NRMSE). Writes a plant file that 'fault-monitor design' takes as it is, with its signal map "
            "and operating point. Exit 2 with one line when the log cannot be identified from (no excitation, "
            "missing signals, too short). An ArduPilot on-board DataFlash log (.bin, or its text form .log) is read "
            "too, with --signals naming its own messages (e.g. AOA.AOA, RATE.P, RCOU.C2) and TimeUS as the clock; "
            "so is a PX4 ULog log (.ulg), with --signals naming its topics (e.g. vehicle_angular_velocity.xyz[1]) "
            "and timestamp as the clock."
        ),
        epilog="Example: fault-monitor identify flight.tlog --out c172p.toml && "
        "fault-monitor design --plant c172p.toml --out gains.toml",
    )
    p.add_argument(
        "tlog",
        metavar="FLIGHT.tlog",
        help="the telemetry log (MAVProxy / QGroundControl format), a DataFlash log (.bin, .log) or a ULog (.ulg)",
    )
    p.add_argument("--out", required=True, metavar="PLANT.toml", help="the plant file to write")
    p.add_argument(
        "--model",
        choices=("short-period", "longitudinal"),
        default="longitudinal",
        help="states: short-period = alpha, q; longitudinal = alpha, q, theta, airspeed (default: longitudinal)",
    )
    p.add_argument(
        "--h",
        type=float,
        metavar="S",
        help="sampling period of the plant, a whole multiple of the "
        "log's own sample spacing (default: that spacing, from the instant message's time stamps)",
    )
    p.add_argument(
        "--tau-min",
        type=float,
        metavar="S",
        default=0.0,
        help="lower bound of the network delay written to the plant (default: 0)",
    )
    p.add_argument(
        "--tau-max",
        type=float,
        metavar="S",
        help="upper bound of the network delay written to the "
        "plant (default: 0.46 h); it may reach past h (a radio or cellular link): the monitor then "
        "carries the commands in flight in its state",
    )
    p.add_argument(
        "--turbulence",
        metavar="LEVEL",
        choices=TURBULENCE_LEVELS,
        help="the turbulence the flight met "
        f"({', '.join(TURBULENCE_LEVELS)}), written beside the gust measured from the log ([disturbance]); "
        "information for detectability, which scales the gust to other levels",
    )
    p.add_argument(
        "--air-only",
        metavar="PLANT.toml",
        help="keep PLANT's model and measure only the air this log "
        "flew in: PLANT is written to --out with its [disturbance] table measured from this log (with "
        "--turbulence LEVEL, the level flown). Identify the dynamics in calm air, then the gust from a "
        "flight in turbulence: a turbulent flight spoils the dynamics' fit. PLANT may be an envelope: the gust is "
        "measured with the point nearest where the log flew (a steady stretch: --window over a level leg) and "
        "written into every point, scaled by its airspeed",
    )
    p.add_argument(
        "--actuator-limit",
        type=float,
        metavar="DEG",
        default=DEFAULT_ACTUATOR_LIMIT,
        help="elevator limit about trim written to [actuator] (default: 25.0; a log shows the "
        "deflections flown, not the aircraft's stops)",
    )
    p.add_argument(
        "--signals",
        metavar="FILE",
        help="a [signals] table naming where alpha, q, theta, airspeed "
        "and the elevator are in the log (default: AOA_SSA.AOA, ATTITUDE.pitchspeed and .pitch, "
        "VFR_HUD.airspeed, ACTUATOR_OUTPUT_STATUS.actuator[0])",
    )
    p.add_argument("--sysid", type=int, metavar="N", help="the vehicle to identify (needed when the log holds several)")
    p.add_argument("--name", help="the plant's name (default: the output file's stem)")
    p.add_argument(
        "--window",
        metavar="START:END",
        type=_window,
        help="identify from one leg of a longer flight: the samples from START to END seconds after the vehicle's "
        "first one (a mission's identification leg at one operating point; fault-monitor envelope assembles the "
        "plants of several legs); default: the whole log",
    )
    p.add_argument(
        "--known-input",
        action="append",
        default=[],
        metavar="SIGNAL",
        dest="known_inputs",
        help="a measured signal the model takes as an input besides the elevator, identified with it and written as "
        "a [known_inputs.linear] column (not a fault): e.g. throttle, which moves with every change of speed; the "
        "log must move it (a mission leg's excite_throttle). Repeat for several",
    )
    p.add_argument(
        "--known-input-lag",
        type=_lag,
        default=DEFAULT_KNOWN_INPUT_LAG,
        metavar="S|auto",
        help="the first-order lag (seconds) through which the known inputs act, identified and estimated with it "
        f"([known_inputs.lag]): an engine's thrust follows its lever (default: {DEFAULT_KNOWN_INPUT_LAG:g}, a piston "
        "engine and propeller; a turbine spools up in several seconds); 'auto': the best held-out fit of "
        f"{', '.join(f'{v:g}' for v in KNOWN_INPUT_LAGS)} s (a longer lag with a larger column often fits as well: "
        "check it on a second flight)",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=run)


def _lag(text: str) -> float | None:
    """``S`` seconds >= 0, or ``auto`` (None: picked by the fit)."""
    if text.strip().lower() == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds >= 0 or 'auto', got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected seconds >= 0 or 'auto', got {text!r}")
    return value


def _window(text: str) -> tuple[float, float]:
    """``START:END`` in seconds (argparse turns a ValueError into its one-line usage error)."""
    start, sep, end = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected START:END in seconds, got {text!r}")
    try:
        return float(start), float(end)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:END in seconds, got {text!r}") from None


def run(args: argparse.Namespace) -> int:
    req = IdentifyRequest(
        log=args.tlog,
        out=args.out,
        model=args.model,
        h=args.h,
        tau_max=args.tau_max,
        tau_min=args.tau_min,
        turbulence=args.turbulence,
        air_only=args.air_only,
        actuator_limit=args.actuator_limit,
        signals=args.signals,
        sysid=args.sysid,
        name=args.name,
        window=args.window,
        known_inputs=tuple(args.known_inputs),
        known_input_lag=args.known_input_lag,
    )
    done = identify_log(req, say=lambda text: print(f"identify: {text}", file=sys.stderr, flush=True))
    if args.json:
        print(json.dumps(done.report()))
        return 0
    if isinstance(done, AirMeasured):
        print(f"measured the air of {req.log} (sysid {done.sysid}) with the model of {req.air_only}: {done.summary}")
        print(
            f"wrote {req.out}: {req.air_only} with that [disturbance] table"
            + (f" (turbulence {req.turbulence})" if req.turbulence else "")
        )
        return 0
    print(_format(done.result, req.log, done.sysid, req.model, done.units))
    print(
        f"wrote {req.out}: tau in [{req.tau_min:g}, {done.tau_max:g}] s, actuator limit {req.actuator_limit:g} deg "
        f"({'given' if req.actuator_limit != DEFAULT_ACTUATOR_LIMIT else 'default'}); "
        f"{done.flight.records} log records in {done.seconds:.2f} s"
    )
    for line in done.flight.inventory.lines():
        print(f"log holds: {line}")
    return 0


def _format(result, path: str, sysid: int, model: str, units: tuple[str, ...]) -> str:
    ex = result.excitation
    unit_of = dict(zip(result.state_names, units, strict=True))
    unit_of.update({name: "deg" for name in result.input_names})
    op = ", ".join(
        f"{name} {value:.4f} {unit_of.get(name, '')}".rstrip() for name, value in result.operating_point.items()
    )
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
    lines.append(
        "fit on held-out data (free run, NRMSE)  "
        + ", ".join(f"{s} {f:.1f} %" for s, f in result.fit_validation.items())
    )
    for note in result.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines)
