"""``fault-monitor demo``: the paper's comparison end to end, the README's main job."""

from __future__ import annotations

import argparse

from monitor.demo.methods import METHODS


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
            "summary.json is left alone."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--out", default="demo-out", metavar="DIR", help="output directory (default: demo-out)")
    parser.add_argument("--plant", default="paper-continuous", metavar="P", help="continuous plant (default: paper-continuous)")
    parser.add_argument("--steps", type=int, default=100, metavar="N", help="samples per run (default: 100)")
    parser.add_argument("--speedup", type=float, default=10.0, metavar="S", help="simulated seconds per wall second (default: 10)")
    parser.add_argument("--fault", default="bias:2@20", metavar="SPEC", help="fault SPEC (default: bias:2@20)")
    parser.add_argument("--delay", default="uniform:0:0.46", metavar="SPEC", help="delay SPEC (default: uniform:0:0.46)")
    parser.add_argument("--wind", default="paper", metavar="SPEC", help="wind SPEC (default: paper)")
    parser.add_argument("--seed", type=int, default=0, help="seed shared by every design's run (default: 0)")
    parser.add_argument("--methods", default=",".join(METHODS), metavar="LIST",
                        help=f"designs to compare, comma-separated (default: {','.join(METHODS)})")
    parser.add_argument("--runs", type=int, metavar="N", help="instead of the live run: Monte-Carlo over N delay seeds, simulation only (no "
                        "daemons), results in DIR/montecarlo.json")
    parser.add_argument("--redesign", action="store_true", help="design again even when DIR/gains/ holds current gains")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.demo.live import Scenario
    from monitor.demo.orchestrate import DemoOptions, run_demo
    from monitor.errors import UserError

    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise UserError(f"--methods: unknown design '{(bad or [''])[0]}' (choose from {', '.join(METHODS)})")
    if args.steps < 2 or not args.speedup > 0 or (args.runs is not None and args.runs < 1):
        raise UserError("--steps must be >= 2, --speedup > 0 and --runs >= 1")
    scenario = Scenario(plant=args.plant, steps=args.steps, speedup=args.speedup, fault=args.fault, delay=args.delay,
                        wind=args.wind, seed=args.seed)
    options = DemoOptions(scenario=scenario, out=args.out, methods=methods, runs=args.runs, redesign=args.redesign,
                          figures=not args.no_figures)
    return run_demo(options)
