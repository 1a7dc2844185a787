"""``fault-monitor detectability``: the smallest elevator bias detected within T seconds at a false-alarm budget."""

from __future__ import annotations

import argparse
import json
import math
import sys

from monitor.wire import TURBULENCE_LEVELS

DESCRIPTION = """\
What fault can be seen? For a plant and its gains, the smallest constant elevator bias that the alarm
(|f_hat| >= threshold for --alarm-samples samples in a row, as `fault-monitor run` raises it) detects within
--within seconds of its onset, and the threshold that achieves it. Give the air the vehicle flies in, one of:

  --disturbance-bound D   |d| <= D always (plant units): the threshold is 1.25 x the proven bound on |f_hat|
                          with no fault (fault-monitor threshold), so wind never raises it, for every delay
                          sequence; the bias is detected surely.
  --turbulence LEVEL      JSBSim's MIL-F-8785C turbulence (light, moderate, severe): the plant's [disturbance]
                          table (a Gauss-Markov d measured in one level) scaled to LEVEL at --altitude; the
                          threshold gives --false-alarms-per-hour crossings (Rice's formula on the stationary
                          f_hat of the linear loop); the bias is detected with --probability
                          (the linear loop in seeded draws of that air).

The step response and the Gaussian figures are at constant delays (the worst of the interval).
--monte-carlo N --aircraft NAME checks a --turbulence answer on N seeded JSBSim flights in process (the
monitor's estimator closing the loop as in the live service): false alarms before onset, the bias at onset,
and per flight the smallest bias detected within T (bisection on short flights). Progress goes to stderr.

An envelope plant file with its gains file (`design --plant ENV.toml`): the prediction at every point with
its own plant and gains, one line each, and the worst point (the largest detectable bias) last; the Monte
Carlo takes a single-point plant."""

EPILOG = """\
Example: fault-monitor detectability --plant c172p.toml --gains gains.toml --turbulence moderate
         fault-monitor detectability --plant c172p.toml --gains gains.toml --turbulence light \\
             --monte-carlo 10 --aircraft c172p --airspeed 100 --altitude 3000
Then:    fault-monitor run ... --alarm-threshold auto --turbulence moderate"""


def register(sub: argparse._SubParsersAction) -> None:
    from monitor.checks import FALSE_ALARMS_PER_HOUR, PROBABILITY, WITHIN_S

    p = sub.add_parser(
        "detectability",
        help="the smallest elevator bias detected within T s at a false-alarm budget",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--plant", required=True, metavar="P", help="preset (paper, paper-continuous) or plant TOML file")
    p.add_argument("--gains", required=True, metavar="GAINS.toml", help="gains file (from fault-monitor design)")
    air = p.add_mutually_exclusive_group(required=True)
    air.add_argument(
        "--turbulence",
        choices=TURBULENCE_LEVELS[1:],
        metavar="LEVEL",
        help="light, moderate or severe (needs the plant's [disturbance] table)",
    )
    air.add_argument("--disturbance-bound", type=float, metavar="D", help="the largest |d(k)|, plant units")
    p.add_argument(
        "--false-alarms-per-hour",
        type=float,
        default=FALSE_ALARMS_PER_HOUR,
        metavar="N",
        help=f"with --turbulence: the false-alarm budget (default: {FALSE_ALARMS_PER_HOUR:g})",
    )
    p.add_argument(
        "--within",
        type=float,
        default=WITHIN_S,
        metavar="T",
        help=f"detected within T seconds of the onset (default: {WITHIN_S:g})",
    )
    p.add_argument(
        "--probability",
        type=float,
        default=PROBABILITY,
        metavar="P",
        help=f"with --turbulence: detected with at least this probability (default: {PROBABILITY:g})",
    )
    p.add_argument(
        "--alarm-samples",
        type=int,
        default=2,
        metavar="S",
        help="the alarm's persistence, as run's --alarm-samples (default: 2)",
    )
    p.add_argument(
        "--altitude",
        type=float,
        default=3000.0,
        metavar="FT",
        help="feet above ground: where the turbulence intensities are compared, and the Monte Carlo's "
        "altitude (default: 3000)",
    )
    mc = p.add_argument_group("Monte Carlo (with --turbulence)")
    mc.add_argument(
        "--monte-carlo",
        type=int,
        default=0,
        metavar="N",
        help="fly N seeded JSBSim flights (seeds --seed .. --seed + N - 1)",
    )
    mc.add_argument("--aircraft", metavar="NAME", help="the JSBSim aircraft the plant models (e.g. c172p)")
    mc.add_argument("--aircraft-dir", metavar="DIR", help="where the aircraft is, if not one JSBSim ships")
    mc.add_argument("--airspeed", type=float, default=100.0, metavar="KT", help="trim airspeed, knots (default: 100)")
    mc.add_argument(
        "--minutes",
        type=float,
        default=6.0,
        metavar="M",
        help="pre-fault flight per seed, where false alarms are counted (default: 6)",
    )
    mc.add_argument("--seed", type=int, default=0, help="first seed (default: 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text report")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    from monitor.errors import UserError

    for name in ("disturbance_bound", "false_alarms_per_hour", "within", "altitude", "airspeed", "minutes"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise UserError(f"--{name.replace('_', '-')} must be a finite number >= 0, got {value:g}")
    if args.monte_carlo < 0:
        raise UserError(f"--monte-carlo must be >= 0, got {args.monte_carlo}")
    if args.monte_carlo and args.turbulence is None:
        raise UserError("--monte-carlo flies in turbulence: give --turbulence LEVEL")
    if args.monte_carlo and not args.aircraft:
        raise UserError("--monte-carlo needs --aircraft NAME (the JSBSim aircraft the plant models)")
    if args.aircraft and not args.monte_carlo:
        raise UserError("--aircraft applies to --monte-carlo N")


def run(args: argparse.Namespace) -> int:
    from monitor.errors import UserError
    from monitor.model.envelope import is_envelope
    from monitor.model.identification import finite_or_none  # JSON has no infinity (an undetectable bias is inf)
    from monitor.service.fleet_file import load_model

    _check(args)
    if args.monte_carlo and is_envelope(args.plant):
        raise UserError(
            f"--monte-carlo flies one plant: {args.plant} is an envelope (check a point with its own plant and "
            "gains files)"
        )
    model = load_model(args.plant, args.gains, force=False)
    if model.envelope is not None:
        return _run_envelope(args, model)
    plant = model.plant
    result = _predict(args, plant, model.gains)
    mc = None
    if args.monte_carlo:
        from monitor.jsbsim_flights import FlightPlan, monte_carlo  # the in-process JSBSim flights (optional)

        plan = FlightPlan(
            args.aircraft,
            airspeed_kt=args.airspeed,
            altitude_ft=args.altitude,
            aircraft_dir=args.aircraft_dir,
            minutes=args.minutes,
            seed=args.seed,
        )
        mc = monte_carlo(
            model,
            result,
            args.monte_carlo,
            plan,
            progress=lambda line: print(f"monte carlo  {line}", file=sys.stderr, flush=True),
        )
    if args.json:
        out = {**result.as_dict(), "plant": plant.source, "gains": str(args.gains), "unit": plant.unit}
        if mc is not None:
            out["monte_carlo"] = {
                **mc.as_dict(),
                "ratio_false_alarms": _ratio(mc.false_alarms_per_hour, mc.predicted_per_hour),
                "ratio_bias": _ratio(mc.smallest_bias_95, result.bias),
                "ratio_fhat_std": _ratio(mc.fhat_std, result.fhat_std),
            }
        print(json.dumps(finite_or_none(out), allow_nan=False))
        return 0
    _print(plant, result, mc, args)
    return 0


def _predict(args: argparse.Namespace, plant, gains_file):
    """Today's prediction for one plant and its gains file."""
    from monitor.checks.detectability import detectability

    return detectability(
        plant,
        gains_file.gains,
        disturbance_bound=args.disturbance_bound,
        turbulence=args.turbulence,
        altitude_ft=args.altitude,
        false_alarms_per_hour=args.false_alarms_per_hour,
        within_s=args.within,
        alarm_samples=args.alarm_samples,
        probability=args.probability,
        report_time_constant=getattr(gains_file, "fault_time_constant", None),
    )


def _run_envelope(args: argparse.Namespace, model) -> int:
    """The prediction at every point (its plant, its gains), one line each, and the largest bias last."""
    from monitor.checks.points import each_point, worst_point
    from monitor.model.identification import finite_or_none

    envelope = model.envelope
    points = [(name, m.plant, m.gains) for name, m in zip(envelope.names, envelope.points, strict=True)]
    results = each_point(points, lambda plant, gf: _predict(args, plant, gf))
    unit = envelope.envelope.first.unit
    rows = [
        {"name": name, **r.as_dict(), "plant": m.plant.source, "gains": str(args.gains), "unit": unit}
        for (name, r), m in zip(results, envelope.points, strict=True)
    ]
    worst, _ = worst_point(results, lambda r: r.bias)
    if args.json:
        out = {"points": rows, "worst": next(r for r in rows if r["name"] == worst)}
        print(json.dumps(finite_or_none(out), allow_nan=False))
        return 0
    for name, r in results:
        print(
            f"point {name}: a bias of {r.bias:.4g} {unit} or more detected within {r.within_s:g} s at threshold "
            f"{r.threshold:.4g} {unit}"
        )
    r = dict(results)[worst]
    print(f"envelope: worst point {worst}: smallest detectable bias {r.bias:.4g} {unit} (threshold {r.threshold:.4g})")
    return 0


def _ratio(a: float, b: float | None) -> float | None:
    return a / b if b and math.isfinite(a) and math.isfinite(b) else None


def _print(plant, r, mc, args) -> None:
    u = plant.unit
    T = f"{r.within_s:g} s"
    if r.mode == "bounded":
        print(f"air            |d| <= {r.disturbance_bound:g} {u} (bounded)")
        print(
            f"no fault       |f_hat| <= {r.noise_bound:.4g} {u}, proven for every delay sequence in "
            f"[{plant.tau_min:g}, {plant.tau_max:g}] s ({r.noise_bound_method})"
        )
        print(
            f"threshold      {r.threshold:.4g} {u} (1.25 x the bound, as run --alarm-threshold auto "
            f"--disturbance-bound {r.disturbance_bound:g}): no false alarm, ever"
        )
        print(
            f"detectable     a bias of {r.bias:.4g} {u} or more is surely detected within {T} "
            f"(alarm by {r.detected_at_s:.2f} s after onset; f_hat has reached {r.step_at:.3f} of the bias)"
        )
    else:
        print(
            f"air            {r.turbulence} turbulence at {r.altitude_ft:g} ft: d has std {r.sigma_d:.4g} {u}, "
            f"time constant {r.time_constant:.3g} s ([disturbance] x {r.sigma_ratio:.3f}, the ratio of JSBSim's "
            f"MIL-F-8785C intensities to the level it was measured in, {plant.disturbance.turbulence})"
        )
        print(
            f"no fault       f_hat std {r.fhat_std:.4g} {u}, lag-one correlation {r.fhat_rho:.4f} (linear loop, "
            f"worst constant delay {r.tau_worst:.4g} s)"
        )
        print(
            f"threshold      {r.threshold:.4g} {u} = {r.threshold / r.fhat_std:.2f} std: "
            f"{r.false_alarms_per_hour:g} false alarm(s) per hour (Rice; an upper bound of raises)"
        )
        print(
            f"detectable     a bias of {r.bias:.4g} {u} or more is detected within {T} with probability "
            f"{r.probability:g} (the linear loop in 4000 seeded draws of that air; median alarm "
            f"{r.detected_at_s:.2f} s after onset)"
        )
    print(f"delays         {r.delays}")
    flag = f"--turbulence {r.turbulence}" if r.mode == "turbulence" else f"--disturbance-bound {r.disturbance_bound:g}"
    print(f"alarm          fault-monitor run ... --alarm-threshold auto {flag} --alarm-samples {r.alarm_samples}")
    if mc is None:
        return
    print(
        f"monte carlo    {mc.flights} JSBSim {mc.aircraft} flights in {mc.turbulence} turbulence, "
        f"{mc.hours:.2f} h before onset ({mc.seconds:.0f} s)"
    )
    if mc.disturbance:
        print(
            f"  d measured   std {mc.disturbance['sigma']:.4g} {u} (table {r.sigma_d:.4g}), lag-one time constant "
            f"{mc.disturbance['time_constant']:.3g} s as identify fits it (table {r.time_constant:.3g} s)"
        )
    print(
        f"  f_hat std    {mc.fhat_std:.4g} {u} observed, {r.fhat_std:.4g} predicted: ratio "
        f"{_fmt(_ratio(mc.fhat_std, r.fhat_std))}"
    )
    for row in mc.crossings:
        print(
            f"  crossings    of +-{row['level']:.3g} {u}: {row['observed_per_hour']:.3g} per hour observed, "
            f"{row['predicted_per_hour']:.3g} predicted"
        )
    print(
        f"  false alarms {mc.false_alarms} in {mc.hours:.2f} h = {mc.false_alarms_per_hour:.3g} per hour observed, "
        f"at most {mc.predicted_per_hour:.3g} predicted"
    )
    cal = mc.calibration
    if cal is None:
        print("  calibrated   - (the flights cross too few levels often enough to fit their tail: fly more)")
    else:
        other = cal["other_fit_per_hour"]
        print(
            f"  calibrated   threshold {cal['threshold']:.4g} {u} for {cal['per_hour']:g} per hour (kept: "
            f"{cal['kept']}; the flights' crossings of {len(cal['levels'])} levels up to {max(cal['levels']):.3g} "
            f"{u} fitted and extrapolated); the predicted {cal['gaussian_threshold']:.4g} gives "
            f"{cal['prediction_per_hour_by_flights']:.3g} per hour by them"
            + (f"; conservative: the other fit gives {other:.3g} per hour at it" if other is not None else "")
            + f"; {mc.false_alarms_at_calibrated} false alarms at it in the flights"
        )
        print(f"  use          --alarm-threshold {cal['threshold']:.4g} on run and analyse in this air")
    times = [t for t in mc.detection_times_s if t is not None]
    spread = f" (after {min(times):.2f} .. {max(times):.2f} s)" if times else ""
    print(
        f"  bias {mc.bias:.4g}    detected within {r.within_s:g} s in {mc.detected_within} of {mc.flights} "
        f"flights{spread}"
    )
    print(
        f"  smallest     bias detected within {r.within_s:g} s: {mc.smallest_bias_95:.4g} {u} in 95 % of the "
        f"flights (per flight {min(mc.smallest_bias):.3g} .. {max(mc.smallest_bias):.3g}); predicted "
        f"{r.bias:.4g}: ratio {_fmt(_ratio(mc.smallest_bias_95, r.bias))}"
    )


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"
