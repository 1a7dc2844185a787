"""Exact discretisation of the continuous plant with an uncertain short input delay (paper Section II-A).

With the sensor sampling at ``k h`` and the command ``u(k)`` reaching the actuator at ``k h + tau``,
``u(k-1)`` acts on ``[k h, k h + tau)`` and ``u(k)`` on ``[k h + tau, (k+1) h)``, so

    x(k+1) = A x(k) + B0(tau) u(k) + B1(tau) u(k-1) + Df f(k) + Dd d(k)

with ``A = e^{A_c h}``, ``B0(tau) = Gamma(h - tau) B_c``, ``B1(tau) = (Gamma(h) - Gamma(h - tau)) B_c`` and
``Gamma(t) = int_0^t e^{A_c s} ds``. Every integral is one matrix exponential of a block (Van Loan)
matrix, so there is no hand-rolled quadrature to get wrong.

Pure functions only: no I/O, no clocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, logm
from scipy.optimize import minimize_scalar

from monitor.errors import UserError

__all__ = [
    "ContinuousModel",
    "Discrete",
    "integral_expm",
    "discretize",
    "b0_b1",
    "F_of_tau",
    "delta_lemma1",
    "delta_exact",
    "reconstruct_continuous",
]


@dataclass(frozen=True)
class ContinuousModel:
    """``x' = A_c x + B_c u + D_cf f + D_cd d``, ``y = C x``."""

    A_c: np.ndarray
    B_c: np.ndarray
    D_cf: np.ndarray
    D_cd: np.ndarray


@dataclass(frozen=True)
class Discrete:
    """The delay-aware discrete matrices of eq. (2) at one delay ``tau``."""

    A: np.ndarray
    B0: np.ndarray
    B1: np.ndarray
    Df: np.ndarray
    Dd: np.ndarray


def integral_expm(A_c: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(e^{A_c t}, int_0^t e^{A_c s} ds)`` from one exponential of ``[[A_c, I], [0, 0]] t``."""
    n = A_c.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = A_c
    block[:n, n:] = np.eye(n)
    E = expm(block * t)
    return E[:n, :n], E[:n, n:]


def b0_b1(model: ContinuousModel, h: float, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """``B0(tau)`` and ``B1(tau)`` of eq. (2); their sum is ``Gamma(h) B_c`` for every ``tau``."""
    if not 0.0 <= tau < h:
        raise ValueError(f"tau = {tau} outside [0, h = {h})")
    _, gamma_h = integral_expm(model.A_c, h)
    _, gamma_split = integral_expm(model.A_c, h - tau)
    B0 = gamma_split @ model.B_c
    return B0, gamma_h @ model.B_c - B0


def discretize(model: ContinuousModel, h: float, tau: float) -> Discrete:
    """All matrices of eq. (2) at delay ``tau``."""
    A, gamma_h = integral_expm(model.A_c, h)
    B0, B1 = b0_b1(model, h, tau)
    return Discrete(A=A, B0=B0, B1=B1, Df=gamma_h @ model.D_cf, Dd=gamma_h @ model.D_cd)


def F_of_tau(model: ContinuousModel, h: float, tau: float, tau_bar: float) -> np.ndarray:
    """The paper's ``F(tau) = int_{h - tau_bar}^{h - tau} e^{A_c t} dt`` (D = I, E = B_c).

    The printed upper limit ``h`` is a typo: only ``h - tau`` makes ``B0(tau) = B0 + F(tau) E`` hold.
    """
    _, g_tau = integral_expm(model.A_c, h - tau)
    _, g_bar = integral_expm(model.A_c, h - tau_bar)
    F: np.ndarray = g_tau - g_bar
    return F


def delta_lemma1(A: np.ndarray, h: float, tau_min: float, tau_bar: float) -> float:
    """Lemma 1 exactly as printed (with the discrete ``sigma_max(A)``).

    Kept to reproduce the paper's 0.3202; it is not a valid bound in general because the bound it
    comes from needs the continuous ``A_c``. Use ``delta_exact`` for a sound figure.
    """
    s = float(np.linalg.svd(A, compute_uv=False)[0])
    delta: float = (np.exp(s * (h - tau_min)) - np.exp(s * (h - tau_bar))) / s
    return delta


def delta_exact(model: ContinuousModel, h: float, tau_min: float, tau_max: float, tau_bar: float) -> float:
    """``max sigma_max(F(tau))`` over ``[tau_min, tau_max]``: a dense grid, then a bounded refinement."""

    def norm_at(tau: float) -> float:
        return float(np.linalg.norm(F_of_tau(model, h, tau, tau_bar), 2))

    if tau_max == tau_min:
        return norm_at(tau_min)
    grid = np.linspace(tau_min, tau_max, 201)
    values = [norm_at(t) for t in grid]
    i = int(np.argmax(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    res = minimize_scalar(lambda t: -norm_at(t), bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    return max(values[i], -float(res.fun))


def reconstruct_continuous(
    A: np.ndarray, Bsum: np.ndarray, Df: np.ndarray, Dd: np.ndarray, h: float
) -> ContinuousModel:
    """The continuous plant behind discrete matrices: ``A_c = logm(A)/h``, inputs from ``Gamma(h)^-1``.

    ``Bsum = B0 + B1`` is the zero-delay input matrix. Fails with a UserError when ``A`` has no real
    logarithm (e.g. a negative real eigenvalue), since then no continuous plant exists.
    """
    eig = np.linalg.eigvals(A)
    if np.any(np.abs(eig) < 1e-300) or np.any((np.abs(eig.imag) < 1e-12) & (eig.real < 0)):
        raise UserError("discrete A has a zero or negative real eigenvalue: no real continuous plant exists")
    log_a = logm(A)
    if np.max(np.abs(np.imag(log_a))) > 1e-9:
        raise UserError("discrete A has no real matrix logarithm: no continuous plant can be reconstructed")
    A_c = np.real(log_a) / h
    _, gamma_h = integral_expm(A_c, h)
    solve = np.linalg.solve
    return ContinuousModel(A_c=A_c, B_c=solve(gamma_h, Bsum), D_cf=solve(gamma_h, Df), D_cd=solve(gamma_h, Dd))
