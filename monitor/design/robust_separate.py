"""A separate design that is robust over the delay interval: the fair baseline next to the integrated one.

The paper's separate baseline (``monitor.design.separate``) designs each part at the nominal delay and
its real loop is unstable once the delay varies; comparing against it only shows that ignoring the delay
fails. Here each part is still designed *alone* (the observer knows nothing of the controller's gains,
the controller nothing of the observer's), but each is robust over the polytope that contains
``B0(tau)``, as a careful engineer designing them apart would make them:

* **observer**: the H-infinity-optimal (L, M) from ``[d; Delta f; v]`` to ``e_f`` where ``v`` enters
  ``e_x`` through ``OBSERVER_MISMATCH_WEIGHT * (B0(tau) - B0)`` at every vertex: the command increments
  a delay other than the nominal one lets through, whatever controller produces them;
* **controller**: (K1, K2) minimising the worst H-infinity norm over the vertices from ``d`` to
  ``[y; CONTROLLER_INCREMENT_WEIGHT * (u(k) - u(k-1))]`` of the loop ``[x; u(k-1)]`` with the fault known:
  increments are what a varying delay turns into disturbance, so they are weighted;
* K3 cancels a constant fault in steady state, as in every design here.

The weights are the smallest round values for which the combined loop of both presets is stable
(docs/explanation/method.md, the design methods); with weights 1 the parts are each robust but the loop is not.
No common certificate is claimed: ``verify`` judges the real loop.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from scipy.optimize import minimize

from monitor.design.result import DesignResult
from monitor.design.separate import observer_alone
from monitor.errors import DesignFailed
from monitor.model.closed_loop import Gains, fault_cancelling_K3
from monitor.model.delay_model import b0_polytope
from monitor.model.norms import hinf_norm
from monitor.model.plant import Plant

__all__ = ["design_robust_separate", "robust_controller_alone"]

OBSERVER_MISMATCH_WEIGHT = 5.0
CONTROLLER_INCREMENT_WEIGHT = 10.0


def _controller_loop(
    plant: Plant, K1: np.ndarray, K2: np.ndarray, B0_tau: np.ndarray, weight: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``[x; u(k-1)]`` at one delay with the fault known: A, B (from d), C (to [y; weight * increment])."""
    m, p = plant.m, plant.p
    B1_tau = plant.B0 + plant.B1 - B0_tau
    A = np.block([[plant.A + B0_tau @ K1 @ plant.C, B0_tau @ K2 + B1_tau], [K1 @ plant.C, K2]])
    B = np.vstack([plant.Dd, np.zeros((m, p))])
    C = np.vstack([np.hstack([plant.C, np.zeros((plant.l, m))]), weight * np.hstack([K1 @ plant.C, K2 - np.eye(m)])])
    return A, B, C


def robust_controller_alone(
    plant: Plant, vertices: list[np.ndarray], weight: float = CONTROLLER_INCREMENT_WEIGHT, max_evaluations: int = 200
) -> tuple[np.ndarray, np.ndarray, float]:
    """(K1, K2) minimising the worst vertex H-infinity norm described above; returns K1, K2 and that norm."""
    m, l = plant.m, plant.l

    def unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return theta[: m * l].reshape(m, l), theta[m * l :].reshape(m, m)

    def cost(theta: np.ndarray) -> float:
        worst = 0.0
        for v in vertices:
            A, B, C = _controller_loop(plant, *unpack(theta), v, weight)
            radius = float(np.max(np.abs(np.linalg.eigvals(A))))
            if radius >= 0.999:
                return 1e6 * radius
            worst = max(worst, hinf_norm(A, B, C, points=256))
        return worst

    res = minimize(cost, np.zeros(m * l + m * m), method="Nelder-Mead", options={"maxfev": max_evaluations})
    if res.fun >= 1e6:
        raise DesignFailed(
            "robust-separate method: no (K1, K2) stabilises every vertex of the delay polytope; no gains written"
        )
    K1, K2 = unpack(res.x)
    return K1, K2, float(res.fun)


def design_robust_separate(plant: Plant, **_ignored: Any) -> DesignResult:
    t0 = time.perf_counter()
    vertices = b0_polytope(plant)
    mismatch = [OBSERVER_MISMATCH_WEIGHT * (v - plant.B0) for v in vertices]
    L, M, gamma_e, solved = observer_alone(plant, mismatch, method="robust-separate")
    t_obs = time.perf_counter() - t0
    K1, K2, gamma_z = robust_controller_alone(plant, vertices)
    return DesignResult(
        method="robust-separate",
        gains=Gains(L=L, M=M, K1=K1, K2=K2, K3=fault_cancelling_K3(plant, K2)),
        gamma_e=gamma_e,
        gamma_z=gamma_z,
        solved=solved,
        build_seconds=0.0,
        solve_seconds=t_obs,
        total_seconds=time.perf_counter() - t0,
        bounds_apply_to="each part alone, robust over the delay polytope: observer [d; delta f; mismatch] -> e_f, "
        "controller d -> [y; weighted increment]; not the real loop",
        notes=[
            f"observer robust to {OBSERVER_MISMATCH_WEIGHT} x (B0(tau) - B0) at {len(vertices)} vertices; controller "
            f"increments weighted {CONTROLLER_INCREMENT_WEIGHT}; designed apart, the real loop is judged by verify"
        ],
    )
