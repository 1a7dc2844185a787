"""``fault-monitor design``: solve a design for a plant and write the gains file (nothing on failure)."""

from __future__ import annotations

import argparse
import math
import sys
import warnings

from monitor.design import METHODS, OBJECTIVES
from monitor.wire import TURBULENCE_LEVELS


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "design",
        help="compute the fault observer and controller gains for a plant and write them to a gains file",
        description=(
            "Design the fault-estimation observer (L, M) and the fault-tolerant controller (K1, K2, K3) for a plant.\n"
            "  certified: one Lyapunov certificate over every delay in the interval (default), objective:\n"
            "             fast (default): f_hat settles two samples after a step fault at the nominal delay and\n"
            "                    stays put when the delay varies; hinf: the smallest H-infinity bound gamma_e\n"
            "  paper:     Theorem 1 of the paper with the minimal repairs (its bounds hold for model (9) only)\n"
            "  separate:  the paper's baseline: observer and controller designed apart at the nominal delay\n"
            "  robust-separate: designed apart too, but each part robust over the whole delay interval\n"
            "An envelope plant file (several operating points, `fault-monitor envelope`): each point gets the\n"
            "chosen design, in --jobs processes, and one common Lyapunov matrix then certifies every point's loop\n"
            "under any switching among the points (exit 1, naming a pair of points, when none exists).\n"
            "Check any result with `fault-monitor verify`."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--plant",
        required=True,
        metavar="P",
        help='preset (paper, paper-continuous) or plant TOML file; an envelope plant file (form = "envelope") '
        "gets each point's design and one certificate over every point",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=None,
        metavar="N",
        help="envelope plant: design the points on a local Dask cluster of N worker processes (default: the CPU "
        "count; 1: in this process)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="envelope plant: design the points on the Dask cluster whose scheduler is at ADDRESS (e.g. "
        "tcp://10.0.0.5:8786, started with `dask scheduler` and `dask worker ADDRESS` on machines that have this "
        "package) instead of a local one",
    )
    parser.add_argument("--method", choices=METHODS, default="certified", help="design method (default: certified)")
    parser.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default=None,
        help="certified method only: fast (the default) or hinf (the joint H-infinity design)",
    )
    parser.add_argument(
        "--mismatch",
        type=float,
        default=None,
        metavar="E",
        help="fast objective: energy of e_f a unit step fault may leave after the two deadbeat samples "
        "at the interval's ends (default: 0.01; larger trades settling for output regulation)",
    )
    parser.add_argument(
        "--fault-time-constant",
        type=float,
        default=None,
        metavar="S",
        help="report f_hat low-passed with this time constant in seconds, for the alarm and every "
        "user of the estimate (the loop keeps the raw estimate); 0: report it raw (default: "
        "1 s in turbulence, see --turbulence; 0 in calm air)",
    )
    parser.add_argument(
        "--turbulence",
        choices=TURBULENCE_LEVELS,
        default=None,
        help="the air the loop will fly in: in turbulence the reported f_hat is low-passed over 1 s "
        "(no false alarms from gusts, detection about 1 s later); default: the level the plant's "
        "[disturbance] table names, else none",
    )
    parser.add_argument(
        "--max-losses",
        type=int,
        default=0,
        metavar="N",
        help="also certify stability through up to N consecutive lost samples or lost/late commands "
        "(any mix, any delays in the interval); the design fails if no certificate exists "
        "(default: 0, losses not certified)",
    )
    parser.add_argument("--out", required=True, metavar="GAINS.toml", help="gains file to write (only on success)")
    parser.add_argument(
        "--weight-y",
        type=float,
        default=0.1,
        metavar="W",
        help="weight of gamma_z^2 (output bound) next to gamma_e^2 in the objective (default: 0.1)",
    )
    parser.add_argument("--quiet", action="store_true", help="print nothing but errors")
    parser.add_argument(
        "--verbose", action="store_true", help="also print every candidate the search evaluates, on stderr"
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.design import run_design
    from monitor.errors import UserError
    from monitor.gains import write_gains
    from monitor.model.plant import load_plant

    if not args.weight_y >= 0:
        raise UserError(f"--weight-y must be >= 0, got {args.weight_y}")
    if args.objective and args.method != "certified":
        raise UserError(f"--objective applies to --method certified only, not {args.method}")
    from monitor.model.loss_model import check_max_losses

    check_max_losses(args.max_losses)
    options = {"weight_y": args.weight_y, "max_losses": args.max_losses}
    if args.objective:
        options["objective"] = args.objective
    if args.mismatch is not None:
        if args.method != "certified" or args.objective == "hinf" or not args.mismatch > 0:
            raise UserError("--mismatch takes a number > 0 and applies to the fast certified design only")
        options["mismatch"] = args.mismatch
    if args.fault_time_constant is not None:
        if not (math.isfinite(args.fault_time_constant) and args.fault_time_constant >= 0):
            raise UserError(f"--fault-time-constant must be >= 0 seconds, got {args.fault_time_constant}")
        options["fault_time_constant"] = args.fault_time_constant
    if args.turbulence is not None:
        options["turbulence"] = args.turbulence
    from monitor.model.envelope import is_envelope

    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be >= 1, got {args.jobs}")
    if is_envelope(args.plant):
        return _run_envelope(args, options)
    if args.scheduler is not None:
        raise UserError(
            "--scheduler: a single-point plant is one design; only an envelope's points are designed on a cluster"
        )
    plant = load_plant(args.plant)
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    say(
        f"designing ({args.method}) for plant '{plant.name}' ({plant.source}), "
        f"tau in [{plant.tau_min}, {plant.tau_max}] s ..."
    )
    if args.method == "certified" and args.verbose and not args.quiet:
        options["progress"] = lambda i, g: say(
            f"  candidate {i:3d}: " + (f"gamma_e = {g:.4f}" if g else "no certificate")
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cvxpy's "may be inaccurate" warnings: inaccurate solves are refused anyway
        result = run_design(args.method, plant, **options)
    write_gains(args.out, result, plant)
    if not args.quiet:
        g = result.gains
        print(f"method     {result.method}" + (f" (objective {result.objective})" if result.objective else ""))
        for name in ("L", "M", "K1", "K2", "K3"):
            print(f"{name:<10} {getattr(g, name).ravel().round(6).tolist()}")
        print(f"gamma_e    {result.gamma_e:.4f}   gamma_z {result.gamma_z:.4f}   ({result.bounds_apply_to})")
        print(
            f"solver     {result.solver_path}; build {result.build_seconds:.3f} s, "
            f"solve {result.solve_seconds:.3f} s, total {result.total_seconds:.3f} s"
        )
        if plant.lags is not None:
            lags = plant.lags
            print(
                f"delay      past one sample: tau in [{plant.tau_min:g}, {plant.tau_max:g}] s is {lags.first} to "
                f"{lags.last} whole samples of h = {plant.h:g} s; the commands in flight (u(k-2) to "
                f"u(k-{lags.last + 1})) are in the loop's state. Used: one polytope per whole-sample part, "
                "and every combination of their vertices."
            )
        else:
            _print_deltas(plant, result.method)
        for note in result.notes:
            print(f"note       {note}")
        print(f"wrote      {args.out}")
    return 0


def _run_envelope(args: argparse.Namespace, options: dict) -> int:
    """``design --plant ENVELOPE.toml``: every point's design in processes, then the common certificate."""
    from monitor.design.envelope import design_envelope
    from monitor.errors import UserError
    from monitor.gains import write_envelope_gains
    from monitor.model.envelope import load_envelope

    if args.max_losses:
        raise UserError("--max-losses is not certified over an envelope yet (the common certificate covers no losses)")
    envelope = load_envelope(args.plant)
    say = None if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        options.pop("max_losses", None)
        design = design_envelope(
            envelope, method=args.method, jobs=args.jobs, say=say, scheduler=args.scheduler, **options
        )
    write_envelope_gains(args.out, design)
    if args.quiet:
        return 0
    print(
        f"envelope   {envelope.name} ({envelope.source}): {len(envelope.points)} points scheduled by "
        f"{', '.join(envelope.schedule)}, tau in [{envelope.tau_min:g}, {envelope.tau_max:g}] s; method {args.method}"
    )
    for point in envelope.points:
        result = design.results[point.name]
        place = ", ".join(f"{s} {point.at[s]:g}" for s in envelope.schedule)
        observer = "  (observer re-designed for the common P)" if point.name in design.redesigned else ""
        print(
            f"point      {point.name:<16} {place:<18} gamma_e {result.gamma_e:.4f}   gamma_z {result.gamma_z:.4f}"
            f"{observer}"
        )
    common = design.common
    print(f"common     gamma {common.gamma:.4f} on w -> e_f; solver {common.solved.describe()}")
    print(
        f"time       points {design.points_seconds:.2f} s in {design.jobs} process(es), common certificate "
        f"{design.certificate_seconds:.2f} s, total {design.total_seconds:.2f} s"
    )
    for note in design.notes:
        print(f"note       {note}")
    print(f"wrote      {args.out}")
    return 0


def _print_deltas(plant, method: str) -> None:
    """The paper's delta next to the exact one: how the design treated a delay within one sample."""
    from monitor.model.delay_model import delta_summary

    deltas = delta_summary(plant)
    print(
        f"delta      Lemma 1 as printed {deltas['delta_lemma1']:.4f}; exact max |F(tau)| {deltas['delta_exact']:.4f}; "
        f"plant file {deltas['delta_file'] or '-'} (tau_bar {deltas['tau_bar']:.4f} s). "
        + (
            "Used: the exact B0(tau) curve, in a polytope."
            if method == "certified"
            else "Used: none (nominal delay)."
            if method == "separate"
            else "Used: the polytope, for each part alone."
            if method == "robust-separate"
            else "Used: none; Theorem 1 treats d_tau as an outside input."
        )
    )
