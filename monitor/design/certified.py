"""Certified joint design of L, M, K1, K2 (and K3) over a polytope that contains every B0(tau).

The chain: plant -> polytope of ``B0(tau)`` (``monitor.model.delay_model``) -> for a controller ``(K1, K2)``,
one convex problem in the observer gains -> an outer search over the controller -> gains + certificate.

Inner problem (convex, Clarabel): for fixed ``K1, K2`` (``K3`` cancels the fault in steady state) the real
closed loop ``xi+ = A_i xi + B_i w`` at every vertex ``i`` is affine in ``[L; M]``. With a slack ``G`` that is
block diagonal between the controller states ``(x~, u~)`` and the observer states ``(e_x, e_f)``,
``G^T A_i = G^T A_K,i - E_o W C_o`` where ``W = G_o^T [L; M]`` is a new variable, so the discrete H-infinity
conditions (de Oliveira et al.; the paper's (16)/(17) with the typos fixed)

    [[P - G - G^T, G^T A_i, G^T B_i, 0], [*, -P, 0, C_e^T], [*, *, -g_e I, 0], [*, *, *, -I]] < 0

for ``e_f`` (matrix P, bound g_e = gamma_e^2) and the same with Q, C_y, g_z for ``y~`` are LMIs. One
common P and Q for every vertex certify stability and both bounds for *arbitrarily time-varying*
``tau(k)``: the loop at any ``tau`` is a convex combination of the vertices and the conditions are convex
in ``(A, B)``. Objective: ``g_e + weight_y * g_z``.

Outer search: ``(K1, K2)`` enter bilinearly with P, so they are searched (Nelder-Mead over their entries)
around the inner problem, which is compiled once with cvxpy parameters and re-solved in milliseconds.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
from scipy.optimize import minimize

from monitor.design.lmi_blocks import brl_margin, hinf_slack_lmi
from monitor.design.result import DesignResult
from monitor.design.solve import SEARCH_PATHS, Solved, SolveFailed, solve_checked, value_of
from monitor.errors import DesignFailed
from monitor.model.closed_loop import Gains, closed_loop, fault_cancelling_K3, observer_indices, steady_state
from monitor.model.delay_model import b0_polytope, nominal_point
from monitor.model.plant import Plant

__all__ = ["design_certified", "ObserverLMI"]

INFEASIBLE = 1e6


@dataclass
class _Solution:
    cost: float
    L: np.ndarray
    M: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    gamma_e: float
    gamma_z: float
    solved: Solved


class ObserverLMI:
    """The inner convex problem, built once for a plant and its polytope and re-solved for each controller."""

    def __init__(self, plant: Plant, vertices: list[np.ndarray], weight_y: float) -> None:
        self.plant = plant
        self.vertices = vertices
        n, q, m, p, l = plant.n, plant.q, plant.m, plant.p, plant.l
        N = 2 * n + q + m
        nw = p + q
        sx, se, sf, su = observer_indices(plant)
        obs = list(range(se.start, sf.stop))
        ctl = list(range(sx.start, sx.stop)) + list(range(su.start, su.stop))
        no, nc = len(obs), len(ctl)
        # Selection matrices: E_o places observer rows, C_o reads e_x (the observer's innovation is C e_x).
        self._E_o = np.zeros((N, no))
        self._E_o[obs, range(no)] = 1.0
        T_c = np.zeros((N, nc))
        T_c[ctl, range(nc)] = 1.0
        C_o = np.zeros((l, N))
        C_o[:, se] = plant.C
        self.P = cp.Variable((N, N), symmetric=True)
        self.Q = cp.Variable((N, N), symmetric=True)
        self.G_o = cp.Variable((no, no))
        self.G_c = cp.Variable((nc, nc))
        self.W = cp.Variable((no, l))
        self.g_e = cp.Variable(nonneg=True)
        self.g_z = cp.Variable(nonneg=True)
        G = self._E_o @ self.G_o @ self._E_o.T + T_c @ self.G_c @ T_c.T
        self.A_params = [cp.Parameter((N, N)) for _ in vertices]
        self.B_params = [cp.Parameter((N, nw)) for _ in vertices]
        loop0 = closed_loop(plant, Gains.zero(plant), nominal_point(plant), steady=(np.zeros((n, q)), np.zeros((m, q))))
        constraints = []  # P, Q > 0 follow from the -P, -Q diagonal blocks
        correction = self._E_o @ self.W @ C_o  # G^T (A_K - E_o [L; M] C_o) = G^T A_K - E_o W C_o
        for A_i, B_i in zip(self.A_params, self.B_params, strict=True):
            GA = G.T @ A_i - correction
            GB = G.T @ B_i
            for X, C_out, g in ((self.P, loop0.C_ef, self.g_e), (self.Q, loop0.C_y, self.g_z)):
                constraints.append(hinf_slack_lmi(X, G, GA, GB, C_out, g))
        self.problem = cp.Problem(cp.Minimize(self.g_e + weight_y * self.g_z), constraints)

    def solve(self, K1: np.ndarray, K2: np.ndarray) -> _Solution | None:
        """Best observer for this controller, or None when no certificate exists for it."""
        plant = self.plant
        K3 = fault_cancelling_K3(plant, K2)
        zero_obs = Gains.zero(plant, K1=K1, K2=K2, K3=K3)
        try:
            steady = steady_state(plant, zero_obs)
        except ValueError:
            return None
        for v, A_p, B_p in zip(self.vertices, self.A_params, self.B_params, strict=True):
            loop = closed_loop(plant, zero_obs, v, steady=steady)
            A_p.value = loop.A
            B_p.value = loop.B

        def recovered() -> Gains:
            LM = np.linalg.solve(value_of(self.G_o).T, value_of(self.W))
            return Gains(L=LM[: plant.n], M=LM[plant.n :], K1=K1, K2=K2, K3=K3)

        def claim() -> float:  # the real loop with the recovered observer, at every vertex: both bounds
            gains = recovered()
            worst = np.inf
            for v in self.vertices:
                loop = closed_loop(plant, gains, v, steady=steady)
                worst = min(
                    worst,
                    brl_margin(value_of(self.P), loop.A, loop.B, loop.C_ef, float(value_of(self.g_e))),
                    brl_margin(value_of(self.Q), loop.A, loop.B, loop.C_y, float(value_of(self.g_z))),
                )
            return worst

        try:
            solved = solve_checked(self.problem, claim, paths=SEARCH_PATHS, retry_infeasible=False)
        except SolveFailed:
            return None
        gains = recovered()
        return _Solution(
            cost=float(self.problem.value),
            L=gains.L,
            M=gains.M,
            P=value_of(self.P),
            Q=value_of(self.Q),
            gamma_e=float(np.sqrt(value_of(self.g_e))),
            gamma_z=float(np.sqrt(value_of(self.g_z))),
            solved=solved,
        )


def _spectral_margin(plant: Plant, vertices: list[np.ndarray], K1: np.ndarray, K2: np.ndarray) -> float:
    """Worst spectral radius of the controller part over the vertices: guides the search where no certificate exists."""
    gains = Gains.zero(plant, K1=K1, K2=K2, K3=fault_cancelling_K3(plant, K2))
    sx, _, _, su = observer_indices(plant)
    idx = list(range(sx.start, sx.stop)) + list(range(su.start, su.stop))
    worst = 0.0
    for v in vertices:
        A = closed_loop(plant, gains, v, steady=(np.zeros((plant.n, plant.q)), np.zeros((plant.m, plant.q)))).A
        worst = max(worst, float(np.max(np.abs(np.linalg.eigvals(A[np.ix_(idx, idx)])))))
    return worst


class _BudgetSpent(Exception):
    """The search's time budget is spent and a certified candidate exists: stop and take the best so far."""


def design_certified(
    plant: Plant,
    weight_y: float = 0.1,
    segments: int = 8,
    max_evaluations: int = 24,
    progress: Callable[[int, float | None], None] | None = None,
    time_budget_s: float | None = None,
) -> DesignResult:
    """Jointly design L, M, K1, K2, K3 with a common-Lyapunov certificate over the whole delay interval.

    ``time_budget_s``: stop the controller search once this much time has passed *and* some candidate is
    certified, keeping the best so far (the default objective's fallback, which must stay quick: each
    candidate is one LMI solve, seconds on a 4-state plant). Every candidate kept is certified, so stopping
    early costs optimality, never the certificate. Without a certified candidate the search goes on.
    """
    t0 = time.perf_counter()
    vertices = b0_polytope(plant, segments=segments)
    lmi = ObserverLMI(plant, vertices, weight_y)
    t_build = time.perf_counter() - t0
    m, l = plant.m, plant.l
    shapes = ((m, l), (m, m))
    cache: dict[tuple[float, ...], _Solution | None] = {}
    solve_time = [0.0]

    def unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        K1 = theta[: m * l].reshape(shapes[0])
        K2 = theta[m * l :].reshape(shapes[1])
        return K1, K2

    def cost(theta: np.ndarray) -> float:
        key = tuple(np.round(theta, 10))
        if (
            key not in cache
            and time_budget_s is not None
            and time.perf_counter() - t0 > time_budget_s
            and any(c is not None for c in cache.values())
        ):
            raise _BudgetSpent
        if key not in cache:
            K1, K2 = unpack(theta)
            margin = _spectral_margin(plant, vertices, K1, K2)
            if margin >= 1.0:
                cache[key] = None
                return INFEASIBLE * margin
            ts = time.perf_counter()
            found = cache[key] = lmi.solve(K1, K2)
            solve_time[0] += time.perf_counter() - ts
            if progress is not None:
                progress(len(cache), found.gamma_e if found else None)
        sol = cache[key]
        return sol.cost if sol is not None else INFEASIBLE

    theta0 = np.zeros(m * l + m * m)
    try:
        result = minimize(
            cost,
            theta0,
            method="Nelder-Mead",
            options={"maxfev": max_evaluations, "xatol": 0.02, "fatol": 0.01, "initial_simplex": _simplex(theta0, 0.3)},
        )
        x_best = result.x
        stopped = False
    except _BudgetSpent:
        certified = [(k, c) for k, c in cache.items() if c is not None]
        x_best = np.array(min(certified, key=lambda kc: kc[1].cost)[0])
        stopped = True
    best = cache.get(tuple(np.round(x_best, 10)))
    if best is None:
        raise DesignFailed(
            f"certified design found no common Lyapunov certificate over tau in [{plant.tau_min}, {plant.tau_max}] "
            f"after {len(cache)} controller candidates (the delay interval may be too wide for this plant)"
        )
    K1, K2 = unpack(x_best)
    gains = Gains(L=best.L, M=best.M, K1=K1, K2=K2, K3=fault_cancelling_K3(plant, K2))
    return DesignResult(
        method="certified",
        objective="hinf",
        gains=gains,
        gamma_e=best.gamma_e,
        gamma_z=best.gamma_z,
        solved=best.solved,
        build_seconds=t_build,
        solve_seconds=solve_time[0],
        total_seconds=time.perf_counter() - t0,
        certificate={"P": best.P, "Q": best.Q, "vertices": np.array([v.ravel() for v in vertices])},
        notes=[
            f"common Lyapunov certificate over {len(vertices)} vertices of a polytope containing B0(tau) "
            f"for every tau in [{plant.tau_min}, {plant.tau_max}] (exact curve, chord error bound)",
            f"K3 cancels a constant fault in steady state; weight on gamma_z^2: {weight_y}",
            f"{len(cache)} controller candidates evaluated"
            + (
                f" (the search stopped at its {time_budget_s:g}-s budget with the best certified one)"
                if stopped
                else ""
            ),
        ],
    )


def _simplex(theta0: np.ndarray, step: float) -> np.ndarray:
    """Initial Nelder-Mead simplex: the start and one step along each coordinate (both signs reachable)."""
    pts = [theta0]
    for i in range(theta0.size):
        e = np.zeros_like(theta0)
        e[i] = step if i % 2 == 0 else -step
        pts.append(theta0 + e)
    return np.array(pts)
