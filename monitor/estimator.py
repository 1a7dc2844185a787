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
    """Everything one vehicle's loop remembers between samples: ``z = [x_hat; f_hat; u(k-1)]``."""

    z: np.ndarray
    n: int
    q: int
    k_last: int | None = None

    @property
    def x_hat(self) -> np.ndarray:
        return self.z[: self.n]

    @property
    def f_hat(self) -> np.ndarray:
        return self.z[self.n : self.n + self.q]

    @property
    def u_prev(self) -> np.ndarray:
        return self.z[self.n + self.q :]


@dataclass(frozen=True)
class StepResult:
    k: int
    u: np.ndarray
    x_hat: np.ndarray  # estimate at k (before the update)
    f_hat: np.ndarray  # estimate at k (before the update)
    residual: np.ndarray
    skipped: int  # samples predicted open-loop because their telemetry never arrived


class Estimator:
    """The FE/FTC law for one plant and one set of gains; state lives in ``EstimatorState``.

    Why one precomputed matrix: the live loop runs this per sample per vehicle, and for these tiny sizes
    numpy's per-call overhead dominates. Substituting the controller into the observer gives, with
    ``z = [x_hat; f_hat; u(k-1)]``, ``[u; z+; r] = T [z; y]``: one matrix product per sample. The
    equations in the module docstring are what ``T`` is built from (``_transition``) and what the tests check.
    """

    def __init__(self, plant: Plant, gains: Gains, max_gap: int = 50) -> None:
        gains.check_shapes(plant)
        self.plant = plant
        self.gains = gains
        self.max_gap = max_gap
        self._T = _transition(plant, gains)
        n, q, m = plant.n, plant.q, plant.m
        N = n + q + m
        predict = np.eye(N)  # a lost sample: no innovation, the actuator held u(k-1)
        predict[:n, :n] = plant.A
        predict[:n, n : n + q] = plant.Df
        predict[:n, n + q :] = plant.B0 + plant.B1
        self._predict_T = predict
        self._m, self._N = m, N

    def initial_state(self) -> EstimatorState:
        p = self.plant
        return EstimatorState(z=np.zeros(p.n + p.q + p.m), n=p.n, q=p.q)

    def step(self, s: EstimatorState, k: int, y) -> StepResult:
        """Process sample k in place. Raises ValueError for a stale or duplicate k (never processed twice)."""
        if s.k_last is not None and k <= s.k_last:
            raise ValueError(f"sample {k} is not newer than {s.k_last}")
        skipped = 0
        if s.k_last is not None:
            gap = k - s.k_last - 1
            if gap > self.max_gap:
                s.z = np.zeros(self._N)
            elif gap:
                s.z = np.linalg.matrix_power(self._predict_T, gap) @ s.z
                skipped = gap
        z = s.z
        out = self._T @ np.concatenate((z, np.asarray(y, dtype=float).ravel()))
        m, N, n, q = self._m, self._N, s.n, s.q
        s.z = out[m : m + N]
        s.k_last = k
        return StepResult(k=k, u=out[:m], x_hat=z[:n], f_hat=z[n : n + q], residual=out[m + N :], skipped=skipped)


def _transition(plant: Plant, g: Gains) -> np.ndarray:
    """``T`` with ``[u; x_hat+; f_hat+; u; r] = T [x_hat; f_hat; u(k-1); y]`` (eqs. 5 and 6 combined)."""
    A, B0, B1, C, Df = plant.A, plant.B0, plant.B1, plant.C, plant.Df
    n, q, m, l = plant.n, plant.q, plant.m, plant.l
    zero = np.zeros
    u_row = np.hstack([zero((m, n)), g.K3, g.K2, g.K1])
    x_row = np.hstack([A - g.L @ C, Df + B0 @ g.K3, B1 + B0 @ g.K2, g.L + B0 @ g.K1])
    f_row = np.hstack([-g.M @ C, np.eye(q), zero((q, m)), g.M])
    r_row = np.hstack([-C, zero((l, q)), zero((l, m)), np.eye(l)])
    return np.vstack([u_row, x_row, f_row, u_row, r_row])
