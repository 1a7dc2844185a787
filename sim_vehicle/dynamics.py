"""Exact integration of the continuous plant between events, with the elevator as a physical actuator.

Why exact: the monitor is judged against this simulator, so integration error must not masquerade as a
fault. Between two events (a sampling instant, a command reaching the actuator, the surface reaching a
rate-limited target) every input is affine in time, and

    x(t0 + T) = e^{A_c T} x0 + Gamma1(T) (B_c u0 + w) + Gamma2(T) B_c r,
    Gamma1(T) = int_0^T e^{A_c s} ds,   Gamma2(T) = int_0^T e^{A_c s} (T - s) ds,

for ``u(t0 + s) = u0 + r s`` and the constant ``w = D_cf f(k) + D_cd d(k)``. All three matrices come from
one exponential of a Van Loan block matrix (the same idea as ``monitor.discretize.integral_expm``, one
block larger for the ramp), so there are no Euler steps and no quadrature tolerance.

The actuator: the commanded deflection is clipped to ``actuator.limit``; with ``actuator.rate_limit`` the
surface slews towards it at that rate (a ramp segment), otherwise it jumps. A ``stuck`` fault freezes
the surface; ``loe`` scales its effect (``u_eff = effectiveness * position``) while its measured
position is unchanged, as for a damaged surface whose position sensor still reads the servo.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from monitor.plant import Actuator, ContinuousModel

__all__ = ["segment_matrices", "Airframe"]


def segment_matrices(A_c: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(e^{A_c T}, Gamma1(T), Gamma2(T))`` from one exponential of ``[[A, I, 0], [0, 0, I], [0, 0, 0]] T``."""
    n = A_c.shape[0]
    block = np.zeros((3 * n, 3 * n))
    block[:n, :n] = A_c
    block[:n, n : 2 * n] = np.eye(n)
    block[n : 2 * n, 2 * n :] = np.eye(n)
    E = expm(block * T)
    return E[:n, :n], E[:n, n : 2 * n], E[:n, 2 * n :]


@dataclass
class Airframe:
    """The vehicle's true state ``x(t)`` and elevator, advanced exactly from event to event.

    Call ``set_interval`` at each sampling instant (fault and wind are held over the interval),
    ``command`` when a command reaches the actuator, and ``advance_to`` before either, with
    non-decreasing times.
    """

    model: ContinuousModel
    actuator: Actuator = field(default_factory=Actuator)
    x: np.ndarray = field(default=None)  # type: ignore[assignment]
    t: float = 0.0
    position: float = 0.0  # measured surface deflection, plant units
    target: float = 0.0  # commanded deflection after clipping
    effectiveness: float = 1.0
    stuck: bool = False
    w: np.ndarray = field(default=None)  # type: ignore[assignment]
    _cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        n = self.model.A_c.shape[0]
        self.x = np.zeros(n) if self.x is None else np.asarray(self.x, dtype=float).copy()
        self.w = np.zeros(n)

    def set_interval(self, f: np.ndarray, d: np.ndarray, effectiveness: float = 1.0,
                     stuck: bool = False, stuck_value: float | None = None) -> None:
        """Hold fault ``f`` and wind ``d`` from now on; apply the deflection faults of this interval."""
        self.w = self.model.D_cf @ np.asarray(f, dtype=float) + self.model.D_cd @ np.asarray(d, dtype=float)
        self.effectiveness = float(effectiveness)
        if stuck and not self.stuck and stuck_value is not None:
            self.position = float(stuck_value)
        released = self.stuck and not stuck
        self.stuck = stuck
        if released and self.actuator.rate_limit is None:
            self.position = self.target  # a freed servo goes to its current command (slews if rate-limited)

    def command(self, u: float) -> None:
        """A command reaches the actuator now: clip it and move (or start slewing) the surface."""
        limit = self.actuator.limit
        self.target = float(np.clip(u, -limit, limit)) if limit is not None else float(u)
        if not self.stuck and self.actuator.rate_limit is None:
            self.position = self.target

    def advance_to(self, t: float) -> None:
        """Integrate exactly from ``self.t`` to ``t`` (splitting where a slewing surface reaches its target)."""
        if t < self.t - 1e-12:
            raise ValueError(f"time goes backwards: {t} < {self.t}")
        while t > self.t:
            T = t - self.t
            rate = 0.0
            gap = self.target - self.position
            slewing = not self.stuck and self.actuator.rate_limit is not None and gap != 0.0
            if slewing:
                rate = float(np.sign(gap)) * self.actuator.rate_limit
                T = min(T, abs(gap) / self.actuator.rate_limit)
            self._integrate(T, rate)
            if slewing:
                done = T >= abs(gap) / self.actuator.rate_limit
                self.position = self.target if done else self.position + rate * T
            self.t = t if T >= t - self.t else self.t + T

    def _integrate(self, T: float, rate: float) -> None:
        phi, g1, g2 = self._matrices(T)
        B = self.model.B_c[:, 0]
        u0 = self.effectiveness * self.position
        self.x = phi @ self.x + g1 @ (B * u0 + self.w) + g2 @ (B * (self.effectiveness * rate))

    def _matrices(self, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = round(T, 12)
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) > 64:
                self._cache.clear()
            hit = self._cache[key] = segment_matrices(self.model.A_c, T)
        return hit

    @property
    def u_effective(self) -> float:
        return self.effectiveness * self.position
