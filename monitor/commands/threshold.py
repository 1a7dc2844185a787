"""``fault-monitor threshold``: a proven bound on |f_hat| with no fault, for alarm thresholds that wind cannot trip."""

from __future__ import annotations

import argparse
import json
import math
import sys


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "threshold",
        help="an alarm threshold wind cannot cross: a proven bound on |f_hat| with no fault and |d| <= D",
        description=(
            "With no fault, zero initial state and a disturbance |d(k)| <= D, how large can |f_hat| get, whatever\n"
            "the delay does inside the plant's interval? The l1 norm of the time-varying impulse response d -> f_hat:\n"
            "the worst delay paths over the vertices of the delay polytope followed exactly, the rest bounded in a\n"
            "common quadratic norm re-checked in numpy. Printed next to the l1 norm at the worst constant delay.\n"
            "Use it as an alarm threshold: `fault-monitor run --alarm-threshold auto --disturbance-bound D`.\n\n"
            "An envelope plant file with its gains file (`design --plant ENV.toml`): every point bounded as above\n"
            "with its own plant and gains, one line each, and the worst point (the largest threshold) last."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--plant", required=True, metavar="P", help="preset (paper, paper-continuous) or plant TOML file"
    )
    parser.add_argument("--gains", required=True, metavar="GAINS.toml", help="gains file (from fault-monitor design)")
    parser.add_argument(
        "--disturbance-bound",
        required=True,
        type=float,
        metavar="D",
        help="the largest |d(k)| to tolerate, plant units (the paper's wind stays within 0.001)",
    )
    parser.add_argument("--json", action="store_true", help='print {"threshold": ..., ...} as one JSON object')
    parser.set_defaults(func=run)


_PROOFS = {
    "paths": "worst-first vertex paths with a common quadratic cost-to-go",
    "blocks": "per-term vertex enumeration with a Lyapunov-norm tail",
}


def _other(bound) -> str:
    """The per-unit figures the chosen proof beat (the invariant ellipsoid alone is the loosest)."""

    def fmt(x: float | None) -> str:
        return "none" if x is None else f"{x:.6g}"

    return (
        f"paths {fmt(bound.bound_paths)} (followed exactly >= {bound.path_depth} samples), blocks "
        f"{fmt(bound.bound_blocks)} ({bound.head_terms} terms exact), ellipsoid alone {fmt(bound.ellipsoid)}"
    )


def run(args: argparse.Namespace) -> int:
    from monitor.checks.threshold import fault_threshold
    from monitor.errors import UserError
    from monitor.gains import read_gains
    from monitor.model.envelope import is_envelope
    from monitor.model.plant import load_plant

    if not (math.isfinite(args.disturbance_bound) and args.disturbance_bound >= 0):
        raise UserError(f"--disturbance-bound must be a finite number >= 0, got {args.disturbance_bound}")
    if is_envelope(args.plant):
        return _run_envelope(args)
    plant = load_plant(args.plant)
    gains_file = read_gains(args.gains)
    gains_file.check_plant(plant)
    bound = fault_threshold(plant, gains_file.gains, args.disturbance_bound)
    if args.json:
        print(json.dumps({**bound.as_dict(), "plant": plant.source, "gains": str(args.gains), "unit": plant.unit}))
        return 0
    D = args.disturbance_bound
    print(
        f"threshold      |f_hat| <= {bound.threshold:.6g} {plant.unit} with no fault and |d| <= {D:g}, "
        f"for every delay sequence in [{plant.tau_min}, {plant.tau_max}] s"
    )
    print(f"per unit |d|   {bound.per_unit_disturbance:.6g} by {_PROOFS[bound.method]} ({bound.seconds:.1f} s)")
    print(f"  proofs       {_other(bound)}")
    print(
        f"constant delay l1 norm {bound.frozen_l1:.6g} per unit |d| at tau = {bound.tau_frozen_worst:.4f} s: "
        f"the bound is {bound.ratio_to_frozen:.2f}x what a constant delay reaches"
    )
    print(
        f"alarm          fault-monitor run ... --alarm-threshold auto --disturbance-bound {D:g}  "
        f"(raises at 1.25 x the bound: {1.25 * bound.threshold:.4g})"
    )
    return 0


def _run_envelope(args: argparse.Namespace) -> int:
    """Every point's bound (its plant, its gains), one line each, and the largest last."""
    from monitor.checks.points import each_point, worst_point
    from monitor.checks.threshold import fault_threshold
    from monitor.gains import read_envelope_gains
    from monitor.model.envelope import load_envelope

    envelope = load_envelope(args.plant)
    gains = read_envelope_gains(args.gains)
    warning = gains.check_envelope(envelope)
    if warning is not None:
        print(f"warning: {warning}", file=sys.stderr)
    points = [(p.name, p.plant, gains.points[p.name]) for p in envelope.points]
    D = args.disturbance_bound
    results = each_point(points, lambda plant, gf: fault_threshold(plant, gf.gains, D))
    unit = envelope.first.unit
    rows = [
        {
            "name": name,
            **bound.as_dict(),
            "plant": envelope.point(name).plant.source,
            "gains": str(args.gains),
            "unit": unit,
        }
        for name, bound in results
    ]
    worst, _ = worst_point(results, lambda bound: bound.threshold)
    if args.json:
        print(json.dumps({"points": rows, "worst": next(r for r in rows if r["name"] == worst)}))
        return 0
    for name, bound in results:
        print(
            f"point {name}: threshold {bound.threshold:.6g} {unit} with no fault and |d| <= {D:g} "
            f"({bound.per_unit_disturbance:.6g} per unit |d|, {bound.ratio_to_frozen:.2f}x the constant delay's)"
        )
    print(f"envelope: worst point {worst}: threshold {dict(results)[worst].threshold:.6g} {unit}")
    return 0
