"""Theorem 1 of the paper, written as close to the printed LMIs as possible, with the minimal repairs.

Model (9): ``zeta = [x; e_x; e_f]``, ``w = [d; d_tau; Delta f]`` with ``d_tau`` in R^n (D = I),

    A_bar = [[A + B0 K1 C, 0, Df], [0, A - L C, Df], [0, -M C, I]],
    B_bar = [[Dd, I, 0], [Dd, I, 0], [0, 0, I]],  C_f = [0 0 I],  C_bar = [C 0 0].

Its gamma's bound model (9) only: ``d_tau = Delta(tau)(u(k) - u(k-1))`` is treated as an outside input and
``(B1 + B0 K2) u(k-1)``, ``(Df + B0 K3) f`` are dropped (Lemma 3). ``verify`` checks the real loop.
Every repair is marked ``REPAIR`` at the line where it applies.
"""

from __future__ import annotations

import time
from typing import Any

import cvxpy as cp
import numpy as np

from monitor.design.lmi_blocks import brl_margin, hinf_slack_lmi
from monitor.design.result import DesignResult
from monitor.design.solve import SolveFailed, solve_checked, value_of
from monitor.errors import DesignFailed
from monitor.model.closed_loop import Gains
from monitor.model.plant import Plant

__all__ = ["design_paper", "lemma3_K2_K3"]


def lemma3_K2_K3(plant: Plant) -> tuple[np.ndarray, np.ndarray]:
    """``K2 = -B0^+ B1``, ``K3 = -B0^+ Df`` (Lemma 3). Exact only if rank[B0 B1] = rank[B0 Df] = rank B0."""
    B0_pinv = np.linalg.pinv(plant.B0)
    return -B0_pinv @ plant.B1, -B0_pinv @ plant.Df


def design_paper(plant: Plant, weight_y: float = 0.1, **_ignored: Any) -> DesignResult:
    """Theorem 1 (repaired): L, M, K1 from LMIs (16)/(17); K2, K3 from Lemma 3 as printed."""
    t0 = time.perf_counter()
    A, B0, C, Df, Dd = plant.A, plant.B0, plant.C, plant.Df, plant.Dd
    n, m, l, q, p = plant.n, plant.m, plant.l, plant.q, plant.p
    N = 2 * n + q
    # REPAIR: full symmetric P and Q (t = 1, 2, 3 blocks coupled). Block-diagonal P_t with block-diagonal G
    # makes (16) exactly zero along an e_f-only direction, so the printed Theorem 1 is never feasible.
    P = cp.Variable((N, N), symmetric=True)
    Q = cp.Variable((N, N), symmetric=True)
    G1 = cp.Variable((n, n))
    G1_hat = cp.Variable((m, m))
    # REPAIR: G couples e_x and e_f (one (n+q) x (n+q) block G23 instead of separate G2, G3).
    G23 = cp.Variable((n + q, n + q))
    X = cp.Variable((m, l))  # X = G1_hat K1           (12)
    Y = cp.Variable((n + q, l))  # Y = G23^T [L; M]    (12), L and M recovered together
    g_e = cp.Variable(nonneg=True)
    g_z = cp.Variable(nonneg=True)
    Z = np.zeros
    G = cp.bmat([[G1, Z((n, n + q))], [Z((n + q, n)), G23]])
    # G^T A_bar, with G1^T B0 K1 C = B0 G1_hat K1 C = B0 X C (the paper's "G1^T B0 ~ B0 G1_hat")
    A_obs = np.block([[A, Df], [Z((q, n)), np.eye(q)]])
    C_obs = np.hstack([C, Z((l, q))])
    GA = cp.bmat(
        [
            [G1.T @ A + B0 @ X @ C, Z((n, n)), G1.T @ Df],
            [Z((n + q, n)), G23.T @ A_obs[:, :n] - Y @ C_obs[:, :n], G23.T @ A_obs[:, n:] - Y @ C_obs[:, n:]],
        ]
    )
    # REPAIR: d_tau lives in R^n (D = I), so B_bar's middle column block is I_n and Psi's is -gamma^2 I_n, not I_m.
    B_bar = np.block([[Dd, np.eye(n), Z((n, q))], [Dd, np.eye(n), Z((n, q))], [Z((q, p)), Z((q, n)), np.eye(q)]])
    GB = G.T @ B_bar
    C_f = np.hstack([Z((q, 2 * n)), np.eye(q)])
    C_bar = np.hstack([C, Z((l, n + q))])
    constraints = [
        # REPAIR: the diagonal blocks of Psi are -P_t / -Q_t (printed +P_t) and Psi_z ends in -I_l (printed -I_q).
        hinf_slack_lmi(P, G, GA, GB, C_f, g_e),  # (16)
        hinf_slack_lmi(Q, G, GA, GB, C_bar, g_z),  # (17)
        # REPAIR: the printed first LMI only bounds |G1^T B0 - B0 G1_hat| < eta with eta > 1, which does
        # not make X = G1_hat K1 recover G1^T B0 K1; the equality makes the change of variables exact.
        G1.T @ B0 == B0 @ G1_hat,
    ]
    problem = cp.Problem(cp.Minimize(g_e + weight_y * g_z), constraints)
    K2, K3 = lemma3_K2_K3(plant)

    def recovered() -> Gains:
        LM = np.linalg.solve(value_of(G23).T, value_of(Y))
        return Gains(L=LM[:n], M=LM[n:], K1=np.linalg.solve(value_of(G1_hat), value_of(X)), K2=K2, K3=K3)

    def claim() -> float:  # model (9) with the recovered L, M, K1: stable with both bounds
        g = recovered()
        A_bar = np.block(
            [[A + B0 @ g.K1 @ C, Z((n, n)), Df], [Z((n, n)), A - g.L @ C, Df], [Z((q, n)), -g.M @ C, np.eye(q)]]
        )
        return min(
            brl_margin(value_of(P), A_bar, B_bar, C_f, float(value_of(g_e))),
            brl_margin(value_of(Q), A_bar, B_bar, C_bar, float(value_of(g_z))),
        )

    t_build = time.perf_counter() - t0
    ts = time.perf_counter()
    try:
        solved = solve_checked(problem, claim)
    except SolveFailed as exc:
        raise DesignFailed(f"paper method (Theorem 1, repaired): {exc}; no gains written") from None
    t_solve = time.perf_counter() - ts
    gains = recovered()
    rank_b1 = np.linalg.matrix_rank(np.hstack([B0, plant.B1]))
    rank_df = np.linalg.matrix_rank(np.hstack([B0, Df]))
    return DesignResult(
        method="paper",
        gains=gains,
        gamma_e=float(np.sqrt(value_of(g_e))),
        gamma_z=float(np.sqrt(value_of(g_z))),
        solved=solved,
        build_seconds=t_build,
        solve_seconds=t_solve,
        total_seconds=time.perf_counter() - t0,
        certificate={"P": value_of(P), "Q": value_of(Q)},
        bounds_apply_to="model (9) only (d_tau as an outside input, nominal tau); not the real loop",
        notes=[
            "Theorem 1 with repairs: full P, Q; G coupling e_x and e_f; -P_t/-Q_t on Psi's diagonal; "
            "d_tau in R^n; exact G1^T B0 = B0 G1_hat",
            f"K2 = -B0^+ B1, K3 = -B0^+ Df (Lemma 3); rank[B0 B1] = {rank_b1}, rank[B0 Df] = {rank_df}, "
            f"rank B0 = {np.linalg.matrix_rank(B0)}: "
            f"Lemma 3 {'holds' if rank_b1 == rank_df == np.linalg.matrix_rank(B0) else 'FAILS'}",
        ],
    )
