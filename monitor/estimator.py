"""Observer (5) and controller (6) for one vehicle, one sample at a time: the maths of the live loop.

Pure and small on purpose: ``monitor run``, the demo's Monte-Carlo and the tests step the same code,
and ``verify`` checks the same matrices in closed form. Per sample k, with measurement ``y(k)``:

    r(k)    = y(k) - C x_hat(k)                                   (residual)
    u(k)    = K1 y(k) + K2 u(k-1) + K3 f_hat(k)                   (controller, eq. 6)
    x_hat(k+1) = A x_hat + B0 u(k) + B1 u(k-1) + Df f_hat + L r   (observer, eq. 5)
    f_hat(k+1) = f_hat + M r

``f_hat(k)`` (the estimate that went into ``u(k)``) is what is reported for sample k, so that
``e_f(k) = f(k) - f_hat(k)`` lines up with the truth at the same k.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.closed_loop import Gains
from monitor.plant import Plant

__all__ = ["EstimatorState", "StepResult", "Estimator"]


@dataclass
class EstimatorState:
    """Everything one vehicle's loop remembers between samples."""

    x_hat: np.ndarray
    f_hat: np.ndarray
    u_prev: np.ndarray
    k_last: int | None = None


@dataclass(frozen=True)
class StepResult:
    k: int
    u: np.ndarray
    x_hat: np.ndarray  # estimate at k (before the update)
    f_hat: np.ndarray  # estimate at k (before the update)
    residual: np.ndarray
    skipped: int  # samples predicted open-loop because their telemetry never arrived


class Estimator:
    """The FE/FTC law for one plant and one set of gains; state lives in ``EstimatorState``."""

    def __init__(self, plant: Plant, gains: Gains, max_gap: int = 50) -> None:
        gains.check_shapes(plant)
        self.plant = plant
        self.gains = gains
        self.max_gap = max_gap

    def initial_state(self) -> EstimatorState:
        p = self.plant
        return EstimatorState(x_hat=np.zeros(p.n), f_hat=np.zeros(p.q), u_prev=np.zeros(p.m))

    def _predict(self, s: EstimatorState) -> None:
        """Advance over a sample whose telemetry was lost: no innovation, and the actuator held u(k-1)."""
        p = self.plant
        s.x_hat = p.A @ s.x_hat + (p.B0 + p.B1) @ s.u_prev + p.Df @ s.f_hat

    def step(self, s: EstimatorState, k: int, y: np.ndarray) -> StepResult:
        """Process sample k in place. Raises ValueError for a stale or duplicate k (never processed twice)."""
        if s.k_last is not None and k <= s.k_last:
            raise ValueError(f"sample {k} is not newer than {s.k_last}")
        skipped = 0
        if s.k_last is not None:
            gap = k - s.k_last - 1
            if gap > self.max_gap:
                fresh = self.initial_state()
                s.x_hat, s.f_hat, s.u_prev = fresh.x_hat, fresh.f_hat, fresh.u_prev
            else:
                for _ in range(gap):
                    self._predict(s)
                skipped = gap
        p, g = self.plant, self.gains
        y = np.asarray(y, dtype=float).reshape(p.l)
        x_hat, f_hat = s.x_hat.copy(), s.f_hat.copy()
        r = y - p.C @ x_hat
        u = g.K1 @ y + g.K2 @ s.u_prev + g.K3 @ f_hat
        s.x_hat = p.A @ x_hat + p.B0 @ u + p.B1 @ s.u_prev + p.Df @ f_hat + g.L @ r
        s.f_hat = f_hat + g.M @ r
        s.u_prev = u
        s.k_last = k
        return StepResult(k=k, u=u, x_hat=x_hat, f_hat=f_hat, residual=r, skipped=skipped)
