"""The certificate of fixed gains: one common Lyapunov pair (P, Q) over the delay polytope, by LMI.

Why a separate analysis step: when the gains are already chosen (the ``fast`` objective pins the observer
in closed form and searches the controller numerically), what is left to prove is convex in the Lyapunov
matrices alone. The Bounded Real Lemma at every vertex ``i`` of the polytope that contains ``B0(tau)``,

    [[-X, 0, A_i^T X, C^T], [0, -g I, B_i^T X, 0], [X A_i, X B_i, -X, 0], [C, 0, 0, -I]] < 0,

with one X for all vertices (P for ``e_f``, Q for ``y~``) proves stability and the bound ``sqrt(g)`` for
arbitrarily time-varying ``tau(k)``, exactly the claim ``verify`` re-checks in numpy. These blocks are
smaller than the slack form the joint design needs (no G), so the solve is a few tens of milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from monitor.closed_loop import Gains, closed_loop, steady_state
from monitor.design.lmi_blocks import EPS
from monitor.design.solve import SolveFailed, solve_problem
from monitor.plant import Plant

__all__ = ["Certificate", "CertificateLMI"]


@dataclass
class Certificate:
    """A solved certificate: the bounds it proves and the matrices ``verify`` re-checks."""

    gamma_e: float
    gamma_z: float
    P: np.ndarray
    Q: np.ndarray
    status: str


def _brl_block(X, A, B, C: np.ndarray, g) -> cp.Constraint:
    """The non-slack discrete Bounded Real Lemma above, affine in X and g for fixed (A, B)."""
    N, nw, k = C.shape[1], B.shape[1], C.shape[0]
    XA, XB = X @ A, X @ B
    block = cp.bmat([
        [-X, np.zeros((N, nw)), XA.T, C.T],
        [np.zeros((nw, N)), -g * np.eye(nw), XB.T, np.zeros((nw, k))],
        [XA, XB, -X, np.zeros((N, k))],
        [C, np.zeros((k, nw)), np.zeros((k, N)), -np.eye(k)],
    ])
    return 0.5 * (block + block.T) << -EPS * np.eye(2 * N + nw + k)


class CertificateLMI:
    """Built once per plant and polytope (cvxpy parameters), re-solved for each set of gains."""

    def __init__(self, plant: Plant, vertices: list[np.ndarray]) -> None:
        self.plant = plant
        self.vertices = vertices
        N = 2 * plant.n + plant.q + plant.m
        nw = plant.p + plant.q
        probe = closed_loop(plant, Gains.zero(plant), plant.B0,
                            steady=(np.zeros((plant.n, plant.q)), np.zeros((plant.m, plant.q))))
        self.P = cp.Variable((N, N), symmetric=True)
        self.Q = cp.Variable((N, N), symmetric=True)
        self.g_e = cp.Variable(nonneg=True)
        self.g_z = cp.Variable(nonneg=True)
        self.A_params = [cp.Parameter((N, N)) for _ in vertices]
        self.B_params = [cp.Parameter((N, nw)) for _ in vertices]
        constraints = []
        for A, B in zip(self.A_params, self.B_params):
            constraints.append(_brl_block(self.P, A, B, probe.C_ef, self.g_e))
            constraints.append(_brl_block(self.Q, A, B, probe.C_y, self.g_z))
        self.problem = cp.Problem(cp.Minimize(self.g_e + self.g_z), constraints)

    def solve(self, gains: Gains) -> Certificate | None:
        """The smallest bounds one common (P, Q) proves for these gains, or None when none exists."""
        try:
            steady = steady_state(self.plant, gains)
        except ValueError:
            return None
        for v, A_p, B_p in zip(self.vertices, self.A_params, self.B_params):
            loop = closed_loop(self.plant, gains, v, steady=steady)
            if np.max(np.abs(np.linalg.eigvals(loop.A))) >= 1.0:
                return None  # unstable at a vertex: no certificate can exist, spare the solver
            A_p.value = loop.A
            B_p.value = loop.B
        try:
            status = solve_problem(self.problem)
        except SolveFailed:
            return None
        return Certificate(gamma_e=float(np.sqrt(self.g_e.value)), gamma_z=float(np.sqrt(self.g_z.value)),
                           P=self.P.value, Q=self.Q.value, status=status)

