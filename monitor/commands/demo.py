"""``fault-monitor demo``: the paper's comparison end to end, the project's first tutorial (docs/tutorials/demo.md)."""

from __future__ import annotations

import argparse

from monitor.demo.methods import METHODS
from monitor.wire import TURBULENCE_LEVELS


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo",
        help="start here: the paper's scenario end to end (design, fly each design live, compare, figures)",
        description=(
            "Run the paper's comparison end to end. Design (or load cached) gains for each design in --methods,\n"
            "check each with `verify`, then for each in turn start sim-vehicle and fault-monitor run as real\n"
            "daemons on free loopback ports with the same scenario and seed, subscribe to the estimates over\n"
            "Zenoh, and print a comparison table. Writes DIR/<design>.rrd (open with `rerun FILE.rrd`, score with\n"
            "`fault-monitor replay FILE.rrd`), DIR/*.png (the paper's Figs. 3-5), DIR/summary.json and the\n"
            "daemons' INFO logs in DIR/logs/. With --runs N: a Monte-Carlo over N delay seeds instead, simulation\n"
            "only (no network, the live vehicle's actuator limit), written to DIR/montecarlo.json; the live run's\n"
            "summary.json is left alone.\n\n"
            "With --aircraft NAME: the same comparison on a JSBSim aircraft. An identification flight (--excite) is\n"
            "logged to DIR/identification/flight.tlog, a short-period and a longitudinal model are identified from\n"
            "it, and every design for each is flown live at 3x with the fault and the delay; the table adds the\n"
            "model and |e_f| and alpha 30 s after onset (default DIR: demo-aircraft)."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--out", metavar="DIR", help="output directory (default: demo-out; demo-aircraft with --aircraft)"
    )
    parser.add_argument(
        "--plant",
        metavar="P",
        help="continuous plant (default: paper-continuous; with --aircraft "
        "the plants are identified from the aircraft's flight)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        metavar="N",
        help="samples per run (default: 100; with --aircraft 45 s of flight at --rate)",
    )
    parser.add_argument(
        "--speedup",
        type=float,
        metavar="S",
        help="simulated seconds per wall second (default: 10; with "
        "--aircraft 3, so that the monitor's few ms per sample stay inside the delay interval at h = 0.05 s)",
    )
    parser.add_argument(
        "--fault",
        metavar="SPEC",
        help="fault SPEC (default: bias:2@20; with --aircraft a 2 deg "
        "elevator bias 5 s into the flight, e.g. bias:2@100 at 20 Hz)",
    )
    parser.add_argument(
        "--delay", metavar="SPEC", help="delay SPEC (default: uniform:0:0.46; with --aircraft uniform over [0, 0.46 h])"
    )
    parser.add_argument("--wind", metavar="SPEC", help="wind SPEC of the linear plant (default: paper)")
    parser.add_argument("--seed", type=int, default=0, help="seed shared by every design's run (default: 0)")
    parser.add_argument(
        "--methods",
        default=",".join(METHODS),
        metavar="LIST",
        help=f"designs to compare, comma-separated (default: {','.join(METHODS)})",
    )
    parser.add_argument(
        "--runs",
        type=int,
        metavar="N",
        help="instead of the live run: Monte-Carlo over N delay seeds, simulation only (no "
        "daemons), results in DIR/montecarlo.json (the linear plant only)",
    )
    parser.add_argument(
        "--redesign",
        action="store_true",
        help="design again even when DIR/gains/ holds current gains "
        "(with --aircraft: fly the identification flight again too)",
    )
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    a = parser.add_argument_group("aircraft (JSBSim): identify the aircraft from a flight, then compare on it")
    a.add_argument("--aircraft", metavar="NAME", help="fly a JSBSim aircraft (e.g. c172p) instead of the paper's plant")
    a.add_argument(
        "--aircraft-dir", metavar="DIR", help="where NAME is, for your own aircraft (see sim-vehicle run --help)"
    )
    a.add_argument("--airspeed", type=float, default=100.0, metavar="KT", help="trim airspeed (default: 100)")
    a.add_argument("--altitude", type=float, default=3000.0, metavar="FT", help="trim altitude (default: 3000)")
    a.add_argument("--rate", type=float, default=20.0, metavar="HZ", help="sample rate, h = 1/HZ (default: 20)")
    a.add_argument(
        "--turbulence",
        default="none",
        choices=TURBULENCE_LEVELS,
        help="JSBSim's turbulence in the live runs (default: none; the identification flight is calm)",
    )
    a.add_argument(
        "--excite",
        default="prbs:1:60",
        metavar="SPEC",
        help="the identification manoeuvre (default: prbs:1:60, +-1 deg for 60 s)",
    )
    a.add_argument(
        "--models",
        default="short-period,longitudinal",
        metavar="LIST",
        help="identified models to compare (default: short-period,longitudinal)",
    )
    parser.set_defaults(func=run)


def _methods(text: str) -> tuple[str, ...]:
    from monitor.errors import UserError

    methods = tuple(m.strip() for m in text.split(",") if m.strip())
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise UserError(f"--methods: unknown design '{(bad or [''])[0]}' (choose from {', '.join(METHODS)})")
    return methods


def run(args: argparse.Namespace) -> int:
    from monitor.errors import UserError

    methods = _methods(args.methods)
    if (
        (args.steps is not None and args.steps < 2)
        or not (args.speedup is None or args.speedup > 0)
        or (args.runs is not None and args.runs < 1)
    ):
        raise UserError("--steps must be >= 2, --speedup > 0 and --runs >= 1")
    if args.aircraft:
        return _run_aircraft(args, methods)
    if args.aircraft_dir:
        raise UserError("--aircraft-dir needs --aircraft NAME")
    from monitor.demo.live import Scenario
    from monitor.demo.orchestrate import DemoOptions, run_demo

    scenario = Scenario(
        plant=args.plant or "paper-continuous",
        steps=args.steps or 100,
        speedup=args.speedup or 10.0,
        fault=args.fault or "bias:2@20",
        delay=args.delay or "uniform:0:0.46",
        wind=args.wind or "paper",
        seed=args.seed,
    )
    options = DemoOptions(
        scenario=scenario,
        out=args.out or "demo-out",
        methods=methods,
        runs=args.runs,
        redesign=args.redesign,
        figures=not args.no_figures,
    )
    return run_demo(options)


def _run_aircraft(args: argparse.Namespace, methods: tuple[str, ...]) -> int:
    """The aircraft demo's defaults scale with the rate: onset 5 s in, 40 s after it, delay below 0.46 h."""
    import math

    from monitor.demo.aircraft import MODELS, AircraftDemoOptions, run_aircraft_demo
    from monitor.demo.live import Aircraft, Scenario
    from monitor.errors import UserError

    for flag, value in (("--plant", args.plant), ("--wind", args.wind), ("--runs", args.runs)):
        if value is not None:
            raise UserError(
                f"{flag} does not apply with --aircraft (the plants are identified from the aircraft's "
                "own flight, its air is --turbulence, and the Monte-Carlo is the linear plant's)"
            )
    if not (math.isfinite(args.rate) and 1.0 <= args.rate <= 200.0):
        raise UserError(f"--rate must be 1-200 Hz, got {args.rate:g}")
    models = tuple(m.strip() for m in args.models.split(",") if m.strip())
    if not models or any(m not in MODELS for m in models):
        raise UserError(f"--models: choose from {', '.join(MODELS)}")
    h = 1.0 / args.rate
    onset = round(5.0 * args.rate)
    aircraft = Aircraft(
        name=args.aircraft,
        airspeed=args.airspeed,
        altitude=args.altitude,
        rate=args.rate,
        turbulence=args.turbulence,
        aircraft_dir=args.aircraft_dir,
    )
    scenario = Scenario(
        plant="",
        steps=args.steps or round(45.0 * args.rate),
        speedup=args.speedup or 3.0,
        fault=args.fault or f"bias:2@{onset}",
        delay=args.delay or f"uniform:0:{round(0.46 * h, 6):g}",
        seed=args.seed,
        aircraft=aircraft,
    )
    options = AircraftDemoOptions(
        scenario=scenario,
        excite=args.excite,
        out=args.out or "demo-aircraft",
        methods=methods,
        models=models,
        redesign=args.redesign,
        figures=not args.no_figures,
    )
    return run_aircraft_demo(options)
