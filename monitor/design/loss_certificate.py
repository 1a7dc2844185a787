"""A certificate that fixed gains keep the loop stable through up to N consecutive losses (LMI in P only).

One P with ``S^T P S <= 0.999^2 P`` for every macro-step ``S`` (``monitor.model.loss_model``: j <= N losses of either
kind, then a delivered sample) at every vertex of the delay polytope proves that every sequence of
delays in the interval and losses with at most N in a row converges: ``V(xi) = xi^T P xi`` decreases
over each macro-step, the macro-step at any delay is a convex combination of the vertex ones, and the
condition is convex in ``S``. ``verify --max-losses`` re-checks P in numpy, and looks for divergent
patterns without it.
"""

from __future__ import annotations

import time

import cvxpy as cp
import numpy as np

from monitor.design.result import DesignResult
from monitor.design.solve import EPS, SolveFailed, most_positive_eigenvalue, solve_checked, value_of
from monitor.errors import DesignFailed
from monitor.model.closed_loop import Gains, steady_state
from monitor.model.delay_model import b0_polytope
from monitor.model.loss_model import macro_steps
from monitor.model.norms import contraction
from monitor.model.plant import Plant

__all__ = ["loss_certificate", "certify_losses", "CONTRACTION"]

CONTRACTION = 0.999  # S^T P S <= CONTRACTION^2 P: every macro-step shrinks ||xi||_P by 0.1 % at least


def loss_certificate(plant: Plant, gains: Gains, vertices: list[np.ndarray], max_losses: int) -> np.ndarray | None:
    """P (normalised P >= I, smallest largest eigenvalue) or None when no common quadratic certificate exists."""
    try:
        steady = steady_state(plant, gains)
    except ValueError:
        return None
    steps = macro_steps(plant, gains, vertices, max_losses, steady)
    if max(float(np.max(np.abs(np.linalg.eigvals(S)))) for S in steps) >= 1.0:
        return None  # a divergent macro-step: no certificate can exist
    N = steps[0].shape[0]
    P = cp.Variable((N, N), symmetric=True)
    t = cp.Variable()
    constraints = [P >> np.eye(N), P << t * np.eye(N)]
    for S in steps:
        lhs = S.T @ P @ S - CONTRACTION**2 * P
        constraints.append(0.5 * (lhs + lhs.T) << -EPS * np.eye(N))
    problem = cp.Problem(cp.Minimize(t), constraints)

    def claim() -> float:  # every macro-step contracts ||xi||_P by CONTRACTION at least, with P >= I
        candidate = value_of(P)
        return min(
            min(-most_positive_eigenvalue(S.T @ candidate @ S - CONTRACTION**2 * candidate) for S in steps),
            -most_positive_eigenvalue(np.eye(N) - candidate) + EPS,
        )

    try:
        solve_checked(problem, claim)
    except SolveFailed:
        return None
    candidate = 0.5 * (value_of(P) + value_of(P).T)
    return candidate if contraction(candidate, steps) < 1.0 else None


def certify_losses(result: DesignResult, plant: Plant, max_losses: int) -> DesignResult:
    """Add the loss certificate to a design's result, or fail the design (nothing is written then)."""
    vertices = (
        [v.reshape(plant.B0.shape) for v in result.certificate["vertices"]]
        if "vertices" in result.certificate
        else b0_polytope(plant)
    )
    t0 = time.perf_counter()
    P = loss_certificate(plant, result.gains, vertices, max_losses)
    result.solve_seconds += time.perf_counter() - t0
    result.total_seconds += time.perf_counter() - t0
    if P is None:
        raise DesignFailed(
            f"{result.method} design: no common Lyapunov certificate for up to {max_losses} consecutive lost samples "
            f"or commands over tau in [{plant.tau_min}, {plant.tau_max}] (try a smaller --max-losses; "
            "`fault-monitor verify --max-losses N` shows which loss patterns diverge)"
        )
    result.certificate = {**result.certificate, "P_loss": P, "vertices": np.array([v.ravel() for v in vertices])}
    result.max_losses = max_losses
    result.notes.append(
        f"stable through up to {max_losses} consecutive lost samples or lost/late commands (any mix), "
        f"any delays in the interval: common Lyapunov P_loss over {len(vertices)} x "
        f"{2 ** (max_losses + 1) - 1} macro-steps"
    )
    return result
