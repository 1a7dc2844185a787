"""Design over an envelope: each point's own design, then ONE certificate for every point's real closed loop.

The chain:

1. **Per point**, the existing design (``run_design``: the method and objective the user chose) on the point's
   own plant. The points are independent problems, so they run on Dask (``monitor.parallel``: a local cluster
   of ``jobs`` worker processes, or the cluster at ``scheduler``).
2. **The common certificate**: one matrix ``P > 0`` and one bound ``g = gamma^2`` with, for every point ``i``
   (its own gains) and every vertex ``v`` of its delay polytope (``monitor.model.delay_model.b0_polytope``),
   the discrete Bounded Real Lemma for ``w = [d; Delta f] -> e_f``

       [[A_iv' P A_iv - P, A_iv' P B_iv, C'], [B_iv' P A_iv, B_iv' P B_iv - g I, 0], [C, 0, -I]] < 0,

   whose top-left block is the stability LMI ``A_iv' P A_iv - P < 0``. Solved with cvxpy/Clarabel and accepted
   only after the numpy re-check of ``monitor.design.solve`` (the BRL matrix and ``P`` at every (point,
   vertex), with margin), whatever the solver's status word.
3. **When no such P exists** for the per-point designs: the pairs of points without a common P are found (the
   same LMI on two points), and the observers (L, M) of a vertex cover of those pairs are re-designed *jointly*,
   with the common P as the constraint, the other points' gains fixed: for fixed controllers the loop is affine
   in ``[L; M]``, and the slack form of ``monitor.design.lmi_blocks`` (one slack G per point, the same P) makes
   it an LMI. Then, if that fails, every point's observer. A re-designed point gets its own certificate again
   (``monitor.design.certificate``) and says so in its notes. If still no P exists, :class:`NoCommonCertificate`
   names a pair that conflicts (exit 1).

What the common P proves: with ``V(xi) = xi' P xi`` decreasing along every point's loop at every delay vertex,
and the loops affine in ``B0(tau)``, any switching among the points at any rate, with any delay sequence in the
interval, keeps the loop stable, and ``||e_f||_2 <= gamma ||w||_2`` from rest. What it does not cover: the
motion of the trim interpolated between the points, and the jump of the fault's steady state ``S_x f`` (which
differs per point) when the point changes, which act as offsets on the state; and interpolated gains (a loop
with gains interpolated between points is not a convex combination of the points' loops): switching is
covered, interpolation is not.
"""

from __future__ import annotations

import itertools
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.design.lmi_blocks import brl_block, brl_margin
from monitor.design.result import DesignResult
from monitor.design.solve import EPS, PATHS, SEARCH_PATHS, Solved, SolveFailed, SolvePath, solve_checked, value_of
from monitor.errors import DesignFailed, UserError
from monitor.model.closed_loop import Gains, LoopMatrices, closed_loop, observer_indices, steady_state
from monitor.model.delay_model import b0_polytope
from monitor.model.envelope import Envelope
from monitor.model.plant import Plant
from monitor.parallel import run_tasks

__all__ = [
    "CommonCertificate",
    "EnvelopeDesign",
    "NoCommonCertificate",
    "STATEMENT",
    "NOT_COVERED",
    "design_envelope",
    "common_certificate",
    "conflicting_pairs",
    "redesign_observers",
    "point_vertices",
]

SEGMENTS = 8  # chords of each point's delay polytope: those of the single-point designs
POINT = "point '{}'"  # how an error in a point's own design or certificate names the point
STATEMENT = (
    "one Lyapunov matrix P for the real closed loop of every point (each with its own gains) at every vertex of "
    "its delay polytope: the loop stays stable and ||e_f|| <= gamma ||w|| (w = [d; Delta f]) under any switching "
    "among the points at any rate, with any delay sequence in the interval"
)
NOT_COVERED = (
    "not covered: the motion of the trim interpolated between the points as the flight moves, and the jump of "
    "the fault's steady state when the point changes, which enter as offsets; and gains interpolated between "
    "points (switching is covered, interpolation is not)"
)

Say = Callable[[str], None]


class NoCommonCertificate(DesignFailed):
    """No common Lyapunov matrix for the envelope's points, even with their observers re-designed for one: exit 1."""

    exit_code = 1


@dataclass
class CommonCertificate:
    """One P and bound over every (point, vertex): what ``verify`` re-checks from the plants and gains alone."""

    P: np.ndarray
    gamma: float
    solved: Solved
    vertices: dict[str, np.ndarray]  # point -> its polytope's vertices, one raveled uncertain point per row
    seconds: float = 0.0


@dataclass
class EnvelopeDesign:
    """Per-point designs (in the envelope's order), the common certificate, and what was re-designed for it."""

    envelope: Envelope
    method: str
    results: dict[str, DesignResult]
    common: CommonCertificate
    redesigned: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)
    jobs: int = 1
    points_seconds: float = 0.0
    certificate_seconds: float = 0.0
    total_seconds: float = 0.0


# -- the per-point problems, in processes --------------------------------------------------------------------------


def _design_point(plant: Plant, method: str, options: dict[str, Any]) -> DesignResult:
    """One point's design (in a worker process): the single-point design, unchanged."""
    from monitor.design import run_design

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cvxpy's "may be inaccurate": every result is re-checked anyway
        return run_design(method, plant, **options)


def _certify_point(
    plant: Plant, gains: Gains, vertices: list[np.ndarray]
) -> tuple[float, float, dict[str, np.ndarray], Solved] | None:
    """A re-designed point's own certificate (P, Q over its polytope), as the fast design certifies its gains."""
    from monitor.design.certificate import CertificateLMI

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cert = CertificateLMI(plant, vertices).solve(gains)
    if cert is None:
        return None
    matrices = {"P": cert.P, "Q": cert.Q, "vertices": np.array([v.ravel() for v in vertices])}
    return cert.gamma_e, cert.gamma_z, matrices, cert.solved


# Each worker process runs one small problem at a time: its BLAS and the solver's thread pool get one thread each.
# Measured on 2 cores, 3 points of a 4-state aircraft in 2 processes: 12.4 s with the default threads (two
# processes spinning two BLAS threads each on two cores), 2.8 s with one.
# -- the common certificate ----------------------------------------------------------------------------------------


def point_vertices(plant: Plant) -> list[np.ndarray]:
    """The vertices of the point's delay polytope: those its single-point design certifies over."""
    return b0_polytope(plant, segments=SEGMENTS)


def _loops(plant: Plant, gains: Gains, vertices: list[np.ndarray]) -> list[LoopMatrices]:
    steady = steady_state(plant, gains)
    return [closed_loop(plant, gains, v, steady=steady) for v in vertices]


def common_certificate(
    loops: dict[str, list[LoopMatrices]], paths: tuple[SolvePath, ...] = PATHS, retry_infeasible: bool = True
) -> tuple[np.ndarray, float, Solved] | None:
    """The smallest ``g`` with one ``P`` for every loop given (the points' loops at their vertices): ``(P, gamma,
    how)``, or None when no P exists (or none the numpy re-check accepts)."""
    import cvxpy as cp

    every = [loop for group in loops.values() for loop in group]
    N = every[0].A.shape[0]
    P = cp.Variable((N, N), symmetric=True)
    g = cp.Variable(nonneg=True)
    constraints = [P >> EPS * np.eye(N)] + [brl_block(P, lp.A, lp.B, lp.C_ef, g) for lp in every]
    problem = cp.Problem(cp.Minimize(g), constraints)

    def claim() -> float:
        return min(brl_margin(value_of(P), lp.A, lp.B, lp.C_ef, float(value_of(g))) for lp in every)

    try:
        solved = solve_checked(problem, claim, paths=paths, retry_infeasible=retry_infeasible)
    except SolveFailed:
        return None
    return value_of(P), float(np.sqrt(float(value_of(g)))), solved


def conflicting_pairs(loops: dict[str, list[LoopMatrices]]) -> list[tuple[str, str]]:
    """The pairs of points whose loops (as designed) have no common P: the same LMI on two points at a time."""
    pairs = []
    for a, b in itertools.combinations(loops, 2):
        if common_certificate({a: loops[a], b: loops[b]}, paths=SEARCH_PATHS, retry_infeasible=False) is None:
            pairs.append((a, b))
    return pairs


def _cover(names: Sequence[str], pairs: list[tuple[str, str]], outlying: dict[str, float]) -> list[str]:
    """A small vertex cover of the conflict graph: greedy, the point in most conflicts first, and of those the one
    farthest from the envelope's middle (``outlying``): conflicts come from the spread, the ends are what differ.
    Measured on a 35-75 m/s aircraft envelope: freeing the two ends gives a common P, the end and its neighbour
    (the first of a tie) does not."""
    left = list(pairs)
    chosen: list[str] = []
    while left:
        degree = {n: sum(n in pair for pair in left) for n in names}
        best = max(names, key=lambda n: (degree[n], outlying[n]))
        chosen.append(best)
        left = [pair for pair in left if best not in pair]
    return [n for n in names if n in chosen]


def redesign_observers(
    plants: dict[str, Plant], gains: dict[str, Gains], vertices: dict[str, list[np.ndarray]], free: Sequence[str]
) -> tuple[dict[str, Gains], np.ndarray, float, Solved] | None:
    """New observers (L, M) for the ``free`` points, the others' gains kept, such that one P certifies them all.

    For a point's fixed controller (K1, K2, K3) its loop is ``A_K - E_o [L; M] C_o`` (``monitor.design.certified``);
    with a slack ``G`` per free point, block diagonal between controller and observer states, and ``W = G_o' [L;
    M]``, the slack BRL with the common P is an LMI. The fixed points enter with the compact BRL in the same P.
    The result is accepted only when the numpy re-check holds with the recovered gains at every (point, vertex).
    """
    import cvxpy as cp

    from monitor.design.lmi_blocks import hinf_slack_lmi

    first = plants[next(iter(plants))]
    n, q, m, l = first.n, first.q, first.m, first.l
    N = 2 * n + q + m
    sx, se, sf, su = observer_indices(first)
    obs = list(range(se.start, sf.stop))
    ctl = list(range(sx.start, sx.stop)) + list(range(su.start, su.stop))
    E_o = np.zeros((N, len(obs)))
    E_o[obs, range(len(obs))] = 1.0
    T_c = np.zeros((N, len(ctl)))
    T_c[ctl, range(len(ctl))] = 1.0
    C_o = np.zeros((l, N))
    C_o[:, se] = first.C
    P = cp.Variable((N, N), symmetric=True)
    g = cp.Variable(nonneg=True)
    constraints = [P >> EPS * np.eye(N)]
    slack: dict[str, tuple[Any, Any]] = {}
    for name, plant in plants.items():
        if name not in free:
            constraints += [brl_block(P, lp.A, lp.B, lp.C_ef, g) for lp in _loops(plant, gains[name], vertices[name])]
            continue
        G_o = cp.Variable((len(obs), len(obs)))
        G_c = cp.Variable((len(ctl), len(ctl)))
        W = cp.Variable((len(obs), l))
        G = E_o @ G_o @ E_o.T + T_c @ G_c @ T_c.T
        probe = Gains.zero(plant, K1=gains[name].K1, K2=gains[name].K2, K3=gains[name].K3)
        for lp in _loops(plant, probe, vertices[name]):
            constraints.append(hinf_slack_lmi(P, G, G.T @ lp.A - E_o @ W @ C_o, G.T @ lp.B, lp.C_ef, g))
        slack[name] = (G_o, W)
    problem = cp.Problem(cp.Minimize(g), constraints)

    def recovered() -> dict[str, Gains]:
        out = dict(gains)
        for name, (G_o, W) in slack.items():
            LM = np.linalg.solve(value_of(G_o).T, value_of(W))
            k = gains[name]
            out[name] = Gains(L=LM[:n], M=LM[n:], K1=k.K1, K2=k.K2, K3=k.K3)
        return out

    def claim() -> float:
        new = recovered()
        Pv, gv = value_of(P), float(value_of(g))
        return min(
            brl_margin(Pv, lp.A, lp.B, lp.C_ef, gv)
            for name, plant in plants.items()
            for lp in _loops(plant, new[name], vertices[name])
        )

    try:
        solved = solve_checked(problem, claim, paths=PATHS[:3])
    except SolveFailed:
        return None
    return recovered(), value_of(P), float(np.sqrt(float(value_of(g)))), solved


# -- the whole design ----------------------------------------------------------------------------------------------


def _where(envelope: Envelope, name: str) -> str:
    point = envelope.point(name)
    return ", ".join(f"{s} {point.at[s]:g}" for s in envelope.schedule)


def design_envelope(
    envelope: Envelope,
    method: str = "certified",
    jobs: int | None = None,
    say: Say | None = None,
    scheduler: str | None = None,
    **options: Any,
) -> EnvelopeDesign:
    """Each point's design (in ``jobs`` processes; default: the CPU count), then the common certificate; see the
    module docstring. ``options`` go to each point's ``run_design``. Raises :class:`NoCommonCertificate` (exit 1)
    naming a pair of points that conflicts when no common P exists, even with re-designed observers.

    With ``jobs > 1`` the workers are started with ``spawn``, which imports the calling script again: call this
    from a script under ``if __name__ == "__main__":`` (the ``fault-monitor`` command does)."""
    tell: Say = say or (lambda text: None)
    if options.get("max_losses"):
        raise UserError("--max-losses is not certified over an envelope (the common certificate covers no losses)")
    options.pop("progress", None)  # a callback does not cross into a worker process
    t0 = time.perf_counter()
    jobs = max(1, int(jobs or os.cpu_count() or 1))
    names = list(envelope.names)
    plants = {p.name: p.plant for p in envelope.points}
    where = {name: _where(envelope, name) for name in names}
    workers = min(jobs, len(names))
    tell(
        f"envelope '{envelope.name}': designing {len(names)} points ({method}) "
        + (
            f"on the Dask cluster at {scheduler}"
            if scheduler is not None
            else f"on a local Dask cluster of {workers} processes"
            if workers > 1
            else "in this process"
        )
    )
    count = [0]

    def designed(name: str, result: DesignResult, seconds: float) -> None:
        count[0] += 1
        tell(
            f"  point '{name}' ({where[name]}): gamma_e {result.gamma_e:.4g}, gamma_z {result.gamma_z:.4g} "
            f"[{count[0]}/{len(names)}, {seconds:.1f} s]"
        )

    tasks = [(n, (plants[n], method, dict(options))) for n in names]
    results = run_tasks(_design_point, tasks, jobs, designed, scheduler, what=POINT)
    t_points = time.perf_counter() - t0
    t1 = time.perf_counter()
    vertices = {n: point_vertices(plants[n]) for n in names}
    gains = {n: results[n].gains for n in names}
    loops = {n: _loops(plants[n], gains[n], vertices[n]) for n in names}
    total_vertices = sum(len(v) for v in vertices.values())
    tell(f"common certificate: one P over {len(names)} points x their delay vertices ({total_vertices} loops) ...")
    found = common_certificate(loops, paths=PATHS[:3], retry_infeasible=False)  # infeasible: the pairs say why
    tell(f"    {'found' if found is not None else 'none'} ({time.perf_counter() - t1:.1f} s)")
    redesigned: list[str] = []
    notes: list[str] = []
    if found is None:
        t_pairs = time.perf_counter()
        pairs = conflicting_pairs(loops)
        tell(f"    {len(names) * (len(names) - 1) // 2} pairs checked ({time.perf_counter() - t_pairs:.1f} s)")
        listed = ", ".join(f"'{a}'/'{b}'" for a, b in pairs) or "none (no pair alone, only all together)"
        tell(f"  no common P for the designed gains; pairs without one: {listed}")
        at = envelope.at_matrix
        span = np.ptp(at, axis=0)
        span[span == 0] = 1.0
        spread = np.linalg.norm((at - at.mean(axis=0)) / span, axis=1)
        tries = [_cover(names, pairs, dict(zip(names, spread.tolist(), strict=True)))] if pairs else []
        if not tries or len(tries[0]) < len(names):
            tries.append(names)
        for free in tries:
            tell(f"  re-designing the observers of {', '.join(repr(f) for f in free)} jointly for one P ...")
            t_try = time.perf_counter()
            again = redesign_observers(plants, gains, vertices, free)
            tell(f"    {'found' if again is not None else 'none'} ({time.perf_counter() - t_try:.1f} s)")
            if again is not None:
                new_gains, P, gamma, solved = again
                found = (P, gamma, solved)
                redesigned = list(free)
                gains = new_gains
                break
        if found is None:
            a, b = pairs[0] if pairs else (names[0], names[-1])
            raise NoCommonCertificate(
                f"envelope '{envelope.name}': no common Lyapunov matrix for points '{a}' ({where[a]}) and '{b}' "
                f"({where[b]})"
                + ("" if pairs else " (every pair has one, all the points together have none)")
                + ", even with the observers re-designed jointly for one: the envelope is too wide for one "
                "certificate of arbitrary switching; narrow it or split it in two"
            )
        notes.append(
            "no common P for the per-point designs (pairs without one: "
            + listed
            + "); the observers (L, M) of "
            + ", ".join(f"'{r}'" for r in redesigned)
            + " were re-designed jointly with the common P as constraint, their controllers (K1, K2, K3) kept"
        )
    P, gamma, solved = found
    t_cert = time.perf_counter() - t1
    tell(f"  common certificate: gamma {gamma:.4g} ({solved.describe()})")
    if redesigned:
        results = _recertify(envelope, results, gains, vertices, redesigned, jobs, tell, where, scheduler)
    common = CommonCertificate(
        P=P,
        gamma=gamma,
        solved=solved,
        vertices={n: np.array([v.ravel() for v in vertices[n]]) for n in names},
        seconds=t_cert,
    )
    notes.insert(0, STATEMENT)
    notes.insert(1, NOT_COVERED)
    return EnvelopeDesign(
        envelope=envelope,
        method=method,
        results=results,
        common=common,
        redesigned=tuple(redesigned),
        notes=notes,
        jobs=workers,
        points_seconds=t_points,
        certificate_seconds=time.perf_counter() - t1,
        total_seconds=time.perf_counter() - t0,
    )


def _recertify(
    envelope: Envelope,
    results: dict[str, DesignResult],
    gains: dict[str, Gains],
    vertices: dict[str, list[np.ndarray]],
    redesigned: list[str],
    jobs: int,
    tell: Say,
    where: dict[str, str],
    scheduler: str | None = None,
) -> dict[str, DesignResult]:
    """Each re-designed point's own certificate (its gamma_e, gamma_z over its own polytope), in processes."""
    plants = {p.name: p.plant for p in envelope.points}

    def done(name: str, cert: tuple[float, float, dict[str, np.ndarray], Solved] | None, seconds: float) -> None:
        if cert is not None:
            tell(f"  point '{name}' ({where[name]}) re-certified: gamma_e {cert[0]:.4g}, gamma_z {cert[1]:.4g}")

    tasks = [(n, (plants[n], gains[n], vertices[n])) for n in redesigned]
    certs = run_tasks(_certify_point, tasks, jobs, done, scheduler, what=POINT)
    out = dict(results)
    for name, cert in certs.items():
        if cert is None:
            raise DesignFailed(f"point '{name}': its re-designed observer has no certificate of its own")
        gamma_e, gamma_z, matrices, solved = cert
        old = results[name]
        out[name] = DesignResult(
            method=old.method,
            objective="envelope",
            gains=gains[name],
            gamma_e=gamma_e,
            gamma_z=gamma_z,
            build_seconds=old.build_seconds,
            solve_seconds=old.solve_seconds,
            total_seconds=old.total_seconds,
            certificate=matrices,
            notes=[
                f"controller (K1, K2, K3) from the point's own design (objective {old.objective or '-'}); observer "
                "(L, M) re-designed jointly with the envelope's other points for their common Lyapunov matrix, so "
                "what that design promised of the observer (e.g. the fast objective's two-sample settling) no "
                "longer holds",
                *(f"the point's own design: {note}" for note in old.notes),
            ],
            solved=solved,
            fault_time_constant=old.fault_time_constant,
        )
    return out
