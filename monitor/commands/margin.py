"""``fault-monitor margin``: the largest delay bound tau_max for which a certified design exists."""

from __future__ import annotations

import argparse
import json
import sys


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "margin",
        help="how much network delay the loop can take: the largest certifiable tau_max, and the cost curve",
        description=(
            "How much delay could the loop take? Bisect on the upper delay bound tau_max in [tau_min, h) (or up to\n"
            "--up-to S, which may reach past h, where the monitor carries the commands in flight): at each\n"
            "probe design the certified gains for the plant with that interval and keep the probe only if its\n"
            "certificate holds. Prints the margin and the curve gamma_e(tau_max) below it; --out writes the gains at\n"
            "the margin (designed for [tau_min, tau_max]; run them with a plant file carrying that tau_max)."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--plant", required=True, metavar="P", help="preset (paper, paper-continuous) or plant TOML file"
    )
    parser.add_argument(
        "--objective",
        choices=("fast", "hinf"),
        default="fast",
        help="certified design objective used at each probe (default: fast)",
    )
    parser.add_argument(
        "--tolerance",
        type=float,
        default=None,
        metavar="S",
        help="stop bisecting when the bracket is narrower than S seconds (default: h/200)",
    )
    parser.add_argument(
        "--up-to",
        type=float,
        default=None,
        metavar="S",
        help="search tau_max up to S seconds, past h if you like (default: h for a plant within one "
        "sample; 3 whole samples above tau_min for a plant whose interval already reaches past h)",
    )
    parser.add_argument("--points", type=int, default=6, metavar="N", help="points of the gamma_e curve (default: 6)")
    parser.add_argument(
        "--json",
        action="store_true",
        help='print {"tau_max": ..., "curve": [{"tau_max": ..., "gamma_e": ...}, ...], "no_certificate_at": '
        "(the probe above the margin that failed), ...} on stdout",
    )
    parser.add_argument("--out", metavar="GAINS.toml", help="write the gains designed at the margin")
    parser.add_argument("--png", metavar="FILE", help="plot gamma_e against tau_max")
    parser.add_argument(
        "--jobs",
        type=int,
        default=None,
        metavar="N",
        help="envelope plant: search the points' margins on a local Dask cluster of N processes (default: the CPU "
        "count)",
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="envelope plant: search them on the Dask cluster at ADDRESS instead"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.checks.margin import delay_margin
    from monitor.errors import UserError
    from monitor.gains import write_gains
    from monitor.model.envelope import is_envelope
    from monitor.model.plant import load_plant

    if is_envelope(args.plant):
        return _run_envelope(args)
    if args.jobs is not None or args.scheduler is not None:
        raise UserError("--jobs and --scheduler are for an envelope plant's points; a single plant is one search")
    plant = load_plant(args.plant)
    if args.tolerance is not None and not 0 < args.tolerance < plant.h:
        raise UserError(f"--tolerance must be in (0, h = {plant.h}), got {args.tolerance}")
    if args.up_to is not None:
        from monitor.model.long_delay import MAX_LAG_PARTS, lag_span

        first, last = lag_span(plant.h, plant.tau_min, args.up_to)
        if not plant.tau_min < args.up_to or last - first + 1 > MAX_LAG_PARTS:
            raise UserError(
                f"--up-to must be above the plant's tau_min = {plant.tau_min:g} s and within "
                f"{MAX_LAG_PARTS} whole samples of it (h = {plant.h:g} s), got {args.up_to}"
            )
    if args.points < 2:
        raise UserError(f"--points must be >= 2, got {args.points}")
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    from monitor.checks.margin import search_ceiling

    top = search_ceiling(plant, args.up_to)
    say(
        f"bisecting tau_max in [{plant.tau_min}, {top:g}) for plant '{plant.name}' "
        f"({args.objective} design at each probe)"
    )
    margin = delay_margin(
        plant,
        tolerance=args.tolerance,
        curve_points=args.points,
        progress=say,
        objective=args.objective,
        up_to=args.up_to,
    )
    if args.out:
        write_gains(args.out, margin.design, margin.plant)
    if args.png:
        _plot(margin, args.png, plant)
    doc = {
        "tau_max": margin.tau_max,
        "curve": margin.curve,
        "h": plant.h,
        "tau_min": plant.tau_min,
        "objective": args.objective,
        "gamma_e_at_margin": margin.design.gamma_e,
        "probes": margin.probes,
        "no_certificate_at": margin.no_certificate_at,
        "plant_interval": [plant.tau_min, plant.tau_max],
    }
    if args.json:
        print(json.dumps(doc))
    else:
        print(
            f"delay margin  tau_max = {margin.tau_max:.4f} s ({margin.tau_max / plant.h:.1%} of h = {plant.h} s; "
            f"the plant file says {plant.tau_max})"
        )
        for point in margin.curve:
            print(f"  tau_max {point['tau_max']:.4f} s   gamma_e {point['gamma_e']:.4f}")
        if args.out:
            print(
                f"wrote gains at the margin to {args.out} (designed for tau in [{plant.tau_min}, {margin.tau_max:.4f}])"
            )
    return 0


def _run_envelope(args: argparse.Namespace) -> int:
    """Every point's margin (in parallel), the worst, and whether the common certificate holds there."""
    import os

    from monitor.checks.envelope_margin import envelope_margin
    from monitor.errors import UserError
    from monitor.gains import write_envelope_gains
    from monitor.model.envelope import load_envelope

    envelope = load_envelope(args.plant)
    if args.tolerance is not None and not 0 < args.tolerance < envelope.h:
        raise UserError(f"--tolerance must be in (0, h = {envelope.h}), got {args.tolerance}")
    for option in ("up_to", "png"):
        if getattr(args, option) is not None:
            raise UserError(f"--{option.replace('_', '-')} is not available for an envelope plant yet")
    jobs = args.jobs if args.jobs is not None else (os.cpu_count() or 1)
    if jobs < 1:
        raise UserError(f"--jobs must be >= 1, got {jobs}")
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    say(f"envelope '{envelope.name}': each point's delay margin ({args.objective} design at each probe)")
    result = envelope_margin(
        envelope, tolerance=args.tolerance, objective=args.objective, jobs=jobs, scheduler=args.scheduler, say=say
    )
    if args.out and result.design is not None:
        write_envelope_gains(args.out, result.design)
    doc = {
        "points": [{"name": name, **vars(m)} for name, m in result.points.items()],
        "worst": result.worst,
        "tau_max": result.tau_max,
        "common_certificate": result.common,
        "gamma_common": result.design.common.gamma if result.design is not None else None,
        "why_not": result.why_not or None,
        "h": envelope.h,
        "plant_interval": [envelope.tau_min, envelope.tau_max],
    }
    if args.json:
        print(json.dumps(doc))
        return 0 if result.common else 1
    for name, m in result.points.items():
        print(f"point {name}: delay margin tau_max = {m.tau_max:.4f} s (gamma_e {m.gamma_e:.4f} there)")
    verdict = (
        f"one certificate covers every point with tau up to it (gamma {result.design.common.gamma:.4g})"
        if result.design is not None
        else f"NO common certificate there: {result.why_not}"
    )
    print(
        f"envelope: worst point {result.worst}: tau_max = {result.tau_max:.4f} s ({result.tau_max / envelope.h:.1%} "
        f"of h = {envelope.h} s; the plant file says {envelope.tau_max}); {verdict}"
    )
    if args.out:
        print(f"wrote the envelope's gains at the margin to {args.out}" if result.design else "wrote nothing")
    return 0 if result.common else 1


def _plot(margin, path: str, plant) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([p["tau_max"] for p in margin.curve], [p["gamma_e"] for p in margin.curve], "o-", label="certified gamma_e")
    ax.axvline(margin.tau_max, color="k", linestyle="--", label=f"margin {margin.tau_max:.3f} s")
    ax.axvline(plant.tau_max, color="grey", linestyle=":", label=f"plant file tau_max {plant.tau_max}")
    ax.set_xlabel("tau_max [s]")
    ax.set_ylabel("gamma_e, the H-inf bound w -> e_f (deg per deg)")
    ax.set_title(f"Delay margin, {plant.name}")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
