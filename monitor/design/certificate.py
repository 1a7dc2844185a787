"""The certificate of fixed gains: one common Lyapunov pair (P, Q) over the delay polytope, by LMI.

Why a separate analysis step: when the gains are already chosen (the ``fast`` objective pins the observer
in closed form and searches the controller numerically), what is left to prove is convex in the Lyapunov
matrices alone. The Bounded Real Lemma at every vertex ``i`` of the polytope that contains ``B0(tau)``,

    [[A_i^T X A_i - X, A_i^T X B_i, C^T], [B_i^T X A_i, B_i^T X B_i - g I, 0], [C, 0, -I]] < 0,

with one X for all vertices (P for ``e_f``, Q for ``y~``, found by two separate problems) proves stability and the
bound ``sqrt(g)`` for arbitrarily time-varying ``tau(k)``, with ``X > 0``: exactly the claim ``verify`` re-checks in
numpy. These blocks are smaller than the slack form the joint design needs (no G), so the solve is a few tens of
milliseconds on a one-sample delay.
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from monitor.design.lmi_blocks import brl_block, brl_margin
from monitor.design.solve import EPS, Solved, SolveFailed, solve_checked, value_of
from monitor.model.closed_loop import Gains, LoopMatrices, closed_loop, steady_state
from monitor.model.delay_model import nominal_point
from monitor.model.plant import Plant

__all__ = ["Certificate", "CertificateLMI"]


@dataclass
class Certificate:
    """A solved certificate: the bounds it proves and the matrices ``verify`` re-checks."""

    gamma_e: float
    gamma_z: float
    P: np.ndarray
    Q: np.ndarray
    solved: Solved


class CertificateLMI:
    """The certificate LMIs of one plant and polytope; :meth:`solve` proves the bounds of one set of gains.

    Why two problems: the objective ``g_e + g_z`` is separable (P, g_e appear only in the e_f blocks; Q, g_z
    only in the y~ blocks), so solving them apart gives the same optimum from two problems of half the
    size. An interior-point step costs more than linearly in the size, and one part that is hard for the
    solver no longer spoils the other. The vertices' matrices enter as constants: each problem is solved
    once per design, and cvxpy compiles a problem with constant data several times faster than one with
    parameters (measured: 2.7 s per compile of the parameterised form on a 4-state aircraft model).
    """

    def __init__(self, plant: Plant, vertices: list[np.ndarray]) -> None:
        self.plant = plant
        self.vertices = vertices
        probe = closed_loop(
            plant,
            Gains.zero(plant),
            nominal_point(plant),
            steady=(np.zeros((plant.n, plant.q)), np.zeros((plant.m, plant.q))),
        )
        self.C_ef, self.C_y = probe.C_ef, probe.C_y

    def solve(self, gains: Gains) -> Certificate | None:
        """The smallest bounds one common (P, Q) proves for these gains, or None when none exists."""
        try:
            steady = steady_state(self.plant, gains)
        except ValueError:
            return None
        loops = [closed_loop(self.plant, gains, v, steady=steady) for v in self.vertices]
        if any(np.max(np.abs(np.linalg.eigvals(loop.A))) >= 1.0 for loop in loops):
            return None  # unstable at a vertex: no certificate can exist, spare the solver
        parts = []
        for C in (self.C_ef, self.C_y):
            part = _common_bound(loops, C)
            if part is None:
                return None
            parts.append(part)
        (P, g_e, solved_e), (Q, g_z, solved_z) = parts
        solved = solved_e if solved_e.margin <= solved_z.margin else solved_z  # the tighter of the two
        if solved_e.path != solved_z.path:
            solved = Solved(
                path=f"{solved_e.path} (e_f) / {solved_z.path} (y)",
                status=solved.status,
                margin=min(solved_e.margin, solved_z.margin),
            )
        return Certificate(gamma_e=float(np.sqrt(g_e)), gamma_z=float(np.sqrt(g_z)), P=P, Q=Q, solved=solved)


def _common_bound(loops: list[LoopMatrices], C: np.ndarray) -> tuple[np.ndarray, float, Solved] | None:
    """One X with the Bounded Real Lemma for output C at every vertex loop, smallest g: (X, g, how), or None."""
    N = loops[0].A.shape[0]
    X = cp.Variable((N, N), symmetric=True)
    g = cp.Variable(nonneg=True)
    # X > 0 explicitly: the compact block alone allows an indefinite X, which would prove nothing (inertia)
    problem = cp.Problem(
        cp.Minimize(g), [X >> EPS * np.eye(N)] + [brl_block(X, loop.A, loop.B, C, g) for loop in loops]
    )

    def claim() -> float:  # what verify re-checks: the bound at every vertex with this one X
        return min(brl_margin(value_of(X), loop.A, loop.B, C, float(value_of(g))) for loop in loops)

    try:
        solved = solve_checked(problem, claim)
    except SolveFailed:
        return None
    return value_of(X), float(value_of(g)), solved
