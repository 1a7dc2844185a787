"""The baseline the paper compares against: observer and controller designed apart, both at the nominal delay.

* Observer: the H-infinity-optimal (L, M) for ``w = [d; Delta f] -> e_f`` of the open-loop error system
  ``[e_x; e_f]+ = ([[A, Df], [0, I]] - [L; M] [C 0]) [e_x; e_f] + ...`` (one LMI), as if the controller and
  the delay did not exist.
* Controller: (K1, K2) minimising the H-infinity norm ``d -> y`` of the nominal loop ``[x; u(k-1)]`` with the
  fault known exactly (so it ignores the observer), searched with Nelder-Mead on a frequency sweep.
* K3: the same steady-state fault cancellation as the certified design, so that the comparison isolates
  what the integrated design changes.
"""

from __future__ import annotations

import time
from typing import Any

import cvxpy as cp
import numpy as np
from scipy.optimize import minimize

from monitor.design.lmi_blocks import brl_margin, hinf_slack_lmi
from monitor.design.result import DesignResult
from monitor.design.solve import Solved, SolveFailed, solve_checked, value_of
from monitor.errors import DesignFailed
from monitor.model.closed_loop import Gains, fault_cancelling_K3
from monitor.model.norms import hinf_norm
from monitor.model.plant import Plant

__all__ = ["design_separate", "observer_alone", "controller_alone"]


def observer_alone(
    plant: Plant, extra_inputs: list[np.ndarray] | None = None, method: str = "separate"
) -> tuple[np.ndarray, np.ndarray, float, Solved]:
    """H-infinity-optimal (L, M) of the error system alone; returns L, M, gamma_e and how the LMI was solved.

    ``extra_inputs``: further n x k input matrices of ``e_x`` to be robust against, one LMI each with the
    same Lyapunov and slack matrices (the robust separate design passes the vertices of ``B0(tau) - B0``,
    the path by which the controller's increments disturb the estimate when the delay is not nominal).
    """
    n, q, l, p = plant.n, plant.q, plant.l, plant.p
    A_o = np.block([[plant.A, plant.Df], [np.zeros((q, n)), np.eye(q)]])
    C_o = np.hstack([plant.C, np.zeros((l, q))])
    B_o = np.block([[plant.Dd, np.zeros((n, q))], [np.zeros((q, p)), np.eye(q)]])
    C_f = np.hstack([np.zeros((q, n)), np.eye(q)])
    X = cp.Variable((n + q, n + q), symmetric=True)
    G = cp.Variable((n + q, n + q))
    Y = cp.Variable((n + q, l))  # Y = G^T [L; M]
    g = cp.Variable(nonneg=True)
    inputs = (
        [B_o]
        if not extra_inputs
        else [np.hstack([B_o, np.vstack([E, np.zeros((q, E.shape[1]))])]) for E in extra_inputs]
    )
    problem = cp.Problem(
        cp.Minimize(g), [*(hinf_slack_lmi(X, G, G.T @ A_o - Y @ C_o, G.T @ B, C_f, g) for B in inputs)]
    )

    def recovered() -> np.ndarray:
        return np.linalg.solve(value_of(G).T, value_of(Y))

    def claim() -> float:  # the error system with the recovered (L, M): stable, and ||w -> e_f|| <= sqrt(g)
        A_cl = A_o - recovered() @ C_o
        return min(brl_margin(value_of(X), A_cl, B, C_f, float(value_of(g))) for B in inputs)

    try:
        solved = solve_checked(problem, claim)
    except SolveFailed as exc:
        raise DesignFailed(f"{method} method, observer LMI: {exc}; no gains written") from None
    LM = recovered()
    return LM[:n], LM[n:], float(np.sqrt(value_of(g))), solved


def _controller_loop(plant: Plant, K1: np.ndarray, K2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nominal ``[x; u(k-1)]`` loop with ``u = K1 y + K2 u(k-1)`` (fault known and cancelled): A, B_d, C_y."""
    m, p = plant.m, plant.p
    A = np.block([[plant.A + plant.B0 @ K1 @ plant.C, plant.B0 @ K2 + plant.B1], [K1 @ plant.C, K2]])
    B = np.vstack([plant.Dd, np.zeros((m, p))])
    C = np.hstack([plant.C, np.zeros((plant.l, m))])
    return A, B, C


def controller_alone(plant: Plant, max_evaluations: int = 200) -> tuple[np.ndarray, np.ndarray, float]:
    """(K1, K2) minimising the nominal ``d -> y`` H-infinity norm; returns K1, K2 and that norm."""
    m, l = plant.m, plant.l

    def unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return theta[: m * l].reshape(m, l), theta[m * l :].reshape(m, m)

    def cost(theta: np.ndarray) -> float:
        A, B, C = _controller_loop(plant, *unpack(theta))
        radius = float(np.max(np.abs(np.linalg.eigvals(A))))
        if radius >= 0.999:
            return 1e6 * radius
        return hinf_norm(A, B, C, points=512)

    res = minimize(
        cost,
        np.zeros(m * l + m * m),
        method="Nelder-Mead",
        options={"maxfev": max_evaluations, "xatol": 1e-4, "fatol": 1e-6},
    )
    if res.fun >= 1e6:
        raise DesignFailed("separate method: no stabilising (K1, K2) found for the nominal plant; no gains written")
    K1, K2 = unpack(res.x)
    return K1, K2, float(res.fun)


def design_separate(plant: Plant, **_ignored: Any) -> DesignResult:
    t0 = time.perf_counter()
    L, M, gamma_e, solved = observer_alone(plant)
    t_obs = time.perf_counter() - t0
    K1, K2, gamma_z = controller_alone(plant)
    gains = Gains(L=L, M=M, K1=K1, K2=K2, K3=fault_cancelling_K3(plant, K2))
    return DesignResult(
        method="separate",
        gains=gains,
        gamma_e=gamma_e,
        gamma_z=gamma_z,
        solved=solved,
        build_seconds=0.0,
        solve_seconds=t_obs,
        total_seconds=time.perf_counter() - t0,
        bounds_apply_to="each part alone at the nominal delay: observer w -> e_f, controller d -> y; not the real loop",
        notes=[
            "observer and controller designed apart at tau_bar, neither aware of the other nor of the delay coupling"
        ],
    )
