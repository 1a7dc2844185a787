"""``fault-monitor verify``: check any gains on the real closed loop, independently of the LMIs."""

from __future__ import annotations

import argparse
import json
import math


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "verify",
        help="check any gains on the real closed loop for every delay in the interval; exit 0 iff stable",
        description=(
            "Build the real closed loop (plant with the u(k-1) state, observer (5), controller (6)) "
            "from the plant and\n"
            "the gains alone, and report: the worst spectral radius over a dense grid of constant delays, the growth\n"
            "rate under randomly time-varying delays, the worst H-infinity norms w=[d; delta f] -> e_f and -> y\n"
            "(frequency sweep), and, when the gains file carries one, the certificate re-checked in numpy.\n"
            "With --max-losses N, also every pattern of at most N consecutive lost samples or lost/late commands\n"
            "(the contract's semantics): divergent patterns are searched (adversarial, bursts, alternating,\n"
            "random) and stability is claimed only with a proof (a norm in which every loss run followed by a\n"
            "delivered sample contracts, at every vertex of the delay polytope; the file's P_loss is re-checked).\n"
            "Exit code 0 only when the loop is stable for every delay in the plant's interval (and proven stable\n"
            "for every loss pattern with --max-losses), 1 otherwise.\n"
            "An envelope plant file with its gains file (`design --plant ENV.toml`): every point checked as above,\n"
            "the common certificate recomputed from the matrices (P > 0, every LMI negative definite by its\n"
            "eigenvalues), and the switched loop simulated with a different random point every sample and random\n"
            "delays; exit 0 only when all of them hold."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--plant", required=True, metavar="P", help="preset (paper, paper-continuous) or plant TOML file"
    )
    parser.add_argument("--gains", metavar="GAINS.toml", help="gains file written by `fault-monitor design`")
    for name, example in (("L", "1.87,1.63"), ("M", "7.0"), ("K1", "-0.2"), ("K2", "0.7"), ("K3", "-0.1")):
        parser.add_argument(
            f"--{name}", metavar="MAT", help=f"gain {name} given inline, e.g. {example} (column; rows with ';')"
        )
    parser.add_argument(
        "--max-losses",
        type=int,
        default=None,
        metavar="N",
        help="also check every pattern with at most N consecutive losses (N >= 0)",
    )
    parser.add_argument("--json", action="store_true", help="print the verdict as one JSON object")
    parser.set_defaults(func=run)


def _inline_gains(args: argparse.Namespace, plant):
    """Gains from --L/--M/--K1 (and optional --K2/--K3, defaulting to the paper's Lemma 3 choice)."""
    from monitor.design.paper import lemma3_K2_K3
    from monitor.errors import UserError
    from monitor.gains import parse_gain_matrix
    from monitor.model.closed_loop import Gains

    missing = [n for n in ("L", "M", "K1") if getattr(args, n) is None]
    if missing:
        raise UserError(
            f"give --gains FILE, or all of --L, --M, --K1 (missing: {', '.join('--' + m for m in missing)})"
        )
    K2_default, K3_default = lemma3_K2_K3(plant)
    mats = {n: parse_gain_matrix(getattr(args, n), n) for n in ("L", "M", "K1")}
    mats["K2"] = parse_gain_matrix(args.K2, "K2") if args.K2 else K2_default
    mats["K3"] = parse_gain_matrix(args.K3, "K3") if args.K3 else K3_default
    assumed = [n for n in ("K2", "K3") if not getattr(args, n)]
    return Gains(**mats), assumed


def run(args: argparse.Namespace) -> int:
    from monitor.checks.verify import verify_gains
    from monitor.errors import UserError
    from monitor.gains import read_gains
    from monitor.model.envelope import is_envelope
    from monitor.model.plant import load_plant

    if is_envelope(args.plant):
        return _run_envelope(args)
    plant = load_plant(args.plant)
    certificate, gamma_e, gamma_z, method, warning, assumed = {}, None, None, "inline", None, []
    filtering = None
    if args.gains:
        if any(getattr(args, n) is not None for n in ("L", "M", "K1", "K2", "K3")):
            raise UserError("give either --gains FILE or inline gains (--L, --M, --K1, ...), not both")
        gf = read_gains(args.gains)
        gf.check_plant(plant)
        gains, certificate, method = gf.gains, gf.certificate, gf.method
        gamma_e, gamma_z = gf.meta.get("gamma_e"), gf.meta.get("gamma_z")
        filtering = gf.fault_time_constant
        if gf.meta.get("plant_hash") not in (None, plant.digest):
            warning = f"gains were designed for another plant ({gf.meta.get('plant')}); checking them on {plant.source}"
            certificate = {}
    else:
        gains, assumed = _inline_gains(args, plant)
    try:
        gains.check_shapes(plant)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if args.max_losses is not None:
        from monitor.model.loss_model import check_max_losses

        check_max_losses(args.max_losses)
    verdict = verify_gains(plant, gains, certificate or None, gamma_e, gamma_z)
    losses = None
    if args.max_losses is not None:
        from monitor.checks.verify_losses import verify_losses

        losses = verify_losses(plant, gains, args.max_losses, certificate or None)
    reported = _reported(verdict, plant, filtering)
    if args.json:
        out = {k: (None if isinstance(v, float) and math.isinf(v) else v) for k, v in verdict.as_dict().items()}
        out.update(fault_time_constant=filtering, reported_error_bound=reported)
        out.update(
            method=method,
            plant=plant.source,
            warning=warning,
            assumed=assumed,
            gains={n: getattr(gains, n).tolist() for n in _GAIN_NAMES},
        )
        if losses is not None:
            out["losses"] = {
                k: (None if isinstance(v, float) and math.isinf(v) else v) for k, v in losses.as_dict().items()
            }
            out["stable_with_losses"] = bool(verdict.stable and losses.stable is True)
        print(json.dumps(out))
    else:
        _print_table(verdict, plant, method, warning, gains, assumed, losses)
        if filtering:
            print(
                f"{'reported f_hat':<32} low-passed, T = {filtering:g} s: error gain <= {reported:.4f} "
                "(the H-inf w -> e_f bound above plus the filter's lag)"
            )
    ok = verdict.stable and (losses is None or losses.stable is True)
    return 0 if ok else 1


_GAIN_NAMES = ("L", "M", "K1", "K2", "K3")


def _run_envelope(args: argparse.Namespace) -> int:
    """``verify --plant ENVELOPE.toml --gains GAINS.toml``: each point, the common certificate, the switched loop."""
    from monitor.checks.envelope import CommonClaim, PointClaim, verify_envelope
    from monitor.errors import UserError
    from monitor.gains import read_envelope_gains
    from monitor.model.envelope import load_envelope

    if not args.gains or any(getattr(args, n) is not None for n in _GAIN_NAMES):
        raise UserError("an envelope plant is verified with its gains file (--gains GAINS.toml), not inline gains")
    if args.max_losses is not None:
        raise UserError("--max-losses is not checked over an envelope yet")
    envelope = load_envelope(args.plant)
    gf = read_envelope_gains(args.gains)
    warning = gf.check_envelope(envelope)
    claims, common = {}, None
    if warning is None:
        for point in envelope.points:
            pf = gf.points[point.name]
            same = pf.meta.get("plant_hash") in (None, point.plant.digest)
            claims[point.name] = PointClaim(
                certificate=pf.certificate if same else {},
                gamma_e=pf.meta.get("gamma_e"),
                gamma_z=pf.meta.get("gamma_z"),
            )
        if gf.common is not None:
            common = CommonClaim(P=gf.common.P, gamma=gf.common.gamma, vertices=gf.common.vertices)
    verdict = verify_envelope(envelope, gf.gains(), claims, common)
    finite = lambda x: None if isinstance(x, float) and math.isinf(x) else x  # noqa: E731
    if args.json:
        out = verdict.as_dict()
        out["points"] = [{k: finite(v) for k, v in p.items()} for p in out["points"]]
        out.update({k: finite(v) for k, v in out.items() if k != "points"})
        out.update(plant=envelope.source, gains=args.gains, schedule=list(envelope.schedule), warning=warning)
        print(json.dumps(out))
    else:
        _print_envelope(verdict, envelope, warning)
    return 0 if verdict.stable else 1


def _print_envelope(v, envelope, warning: str | None) -> None:
    fmt = lambda x: "-" if x is None else ("inf" if math.isinf(x) else f"{x:.4f}")  # noqa: E731
    print(
        f"envelope   {envelope.name} ({envelope.source}): {len(envelope.points)} points scheduled by "
        f"{', '.join(envelope.schedule)}, tau in [{envelope.tau_min:g}, {envelope.tau_max:g}] s"
    )
    for check in v.points:
        c = check.verdict
        place = ", ".join(f"{s} {envelope.point(check.name).at[s]:g}" for s in envelope.schedule)
        cert = {True: "valid", False: "INVALID", None: "none"}[c.certificate_valid]
        print(
            f"point      {check.name:<16} {place:<18} {'stable' if c.stable else 'UNSTABLE':<9} rho_max "
            f"{fmt(c.rho_max)}  rho(tv tau) {fmt(c.rho_time_varying)}  H-inf w->e_f {fmt(c.hinf_ef)}  "
            f"own certificate {cert}"
        )
    print(
        f"common     {'VALID' if v.common_certificate else 'INVALID'}: gamma {fmt(v.gamma_common)}; {v.common_detail}"
    )
    print(
        f"switching  {'bounded' if v.switching_bounded else 'GROWS'}: a different random point every sample, "
        f"random delays, {v.switching_samples} samples: largest amplification {v.switching_sim_max:.4g}, growth "
        f"{v.switching_sim_growth:.6f} per sample over the second half"
    )
    print(
        "verdict    "
        + (
            "STABLE: every point, the common certificate (any switching, any delays) and the simulation hold"
            if v.stable
            else "NOT PROVEN STABLE over the envelope"
        )
    )
    if warning:
        print(f"warning    {warning}")


def _reported(verdict, plant, filtering: float | None) -> float | None:
    """The reported estimate's error gain when the gains file low-passes it (from verify's own H-inf figure)."""
    from monitor.design import reported_error_bound

    if not filtering or math.isinf(verdict.hinf_ef):
        return None
    return reported_error_bound(verdict.hinf_ef, plant.h, filtering)


def _print_table(v, plant, method: str, warning: str | None, gains, assumed: list[str], losses=None) -> None:
    """The verdict, with every gain it was reached with (K2/K3 marked when they were assumed, not given)."""
    fmt = lambda x: "-" if x is None else ("inf" if isinstance(x, float) and math.isinf(x) else f"{x:.4f}")  # noqa: E731
    rows = [
        ("plant", f"{plant.name} ({plant.source}), tau in [{plant.tau_min}, {plant.tau_max}] s"),
        ("gains", method),
        *(
            (f"  {n}", str(getattr(gains, n).tolist()) + ("  (assumed: Lemma 3, as printed)" if n in assumed else ""))
            for n in _GAIN_NAMES
        ),
        ("verdict", "STABLE for every delay in the interval" if v.stable else "UNSTABLE"),
        ("rho_max (constant tau)", f"{fmt(v.rho_max)} at tau = {v.tau_worst:.4f}"),
        ("rho, time-varying tau", fmt(v.rho_time_varying)),
        (
            "H-inf w -> e_f",
            f"{fmt(v.hinf_ef)} (worst at tau = {v.tau_hinf_worst:.4f}; claimed {fmt(v.gamma_e_claimed)})",
        ),
        ("H-inf w -> y", f"{fmt(v.hinf_y)} (claimed {fmt(v.gamma_z_claimed)})"),
        ("steady-state |y| per unit fault", fmt(v.fault_leak)),
        (
            "certificate",
            {True: "valid", False: "INVALID", None: "none"}[v.certificate_valid] + f": {v.certificate_detail}",
        ),
        ("claimed bounds hold", {True: "yes", False: "no", None: "-"}[v.bound_holds]),
    ]
    if losses is not None:
        verdict = {True: "STABLE (proven)", False: "UNSTABLE", None: "NOT PROVEN"}[losses.stable]
        rows += [
            (f"losses (<= {losses.max_losses} in a row)", verdict),
            ("  worst growth found", f"{fmt(losses.growth_lower_bound)} per sample ({losses.worst_pattern})"),
            ("  proof", losses.proof),
        ]
    if warning:
        rows.append(("warning", warning))
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
