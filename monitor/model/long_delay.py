"""Delays past one sample: the sampled plant with the commands still in flight carried in its state.

A command u(k) sent at ``k h`` reaches the actuator at ``k h + tau(k)``, ``tau`` in ``[tau_min, tau_max]``, and
``tau_max`` may be several h. The actuator applies each command when it arrives unless a newer one has
already acted (the link rule; an older command arriving after a newer one is stale and ignored). Over
``[k h, (k+1) h)`` the deflection is then ``u(k-j)`` from ``a_j`` to ``a_{j-1}``, where ``a_j`` (in ``[0, h]``,
from the interval's start) is when ``u(k-j)`` or a newer command first acted. With
``G(a) = int_a^h e^{A_c (h - s)} ds B_c`` (the ``B0`` of a delay ``a < h``; ``G(0)`` is the whole interval's
input matrix and ``G(h) = 0``), summing by parts:

    x(k+1) = A x(k) + sum_{j=first..last} G(a_j) (u(k-j) - u(k-j-1)) + G(0) u(k-last-1) + Df f + Dd d

with ``first = floor(tau_min / h)``, ``last = floor(tau_max / h)`` and each ``a_j`` confined to
``[clip(tau_min - j h), clip(tau_max - j h)]`` (clipped to ``[0, h]``): ``u(k-j)`` left at ``(k-j) h + tau``.

Why this form: it is affine in the ``G(a_j)``, and each lies on the same curve as today's ``B0(tau)``, so each
gets a polytope as before (``monitor.model.delay_model``) and the loop at *any* arrival pattern, whatever the
order in which the whole-sample parts switch from one sample to the next, is a convex combination of the
vertices of their product. One common Lyapunov matrix over those vertices certifies every switching
sequence: the switched system of the whole-sample parts needs no mode enumeration. For ``last = 0`` the
form is eq. (2) exactly: ``G(a_0) = B0(tau)`` and ``G(0) - G(a_0) = B1(tau)``.

The state is ``[x; u(k-2); ...; u(k-last-1)]``: with the ``u(k)`` and ``u(k-1)`` that the observer and the
controller already carry (the ``B0`` and ``B1`` terms), every command that can still act is in the loop.
What varies with the delay is then ``A`` as well as ``B0`` and ``B1``; ``monitor.model.closed_loop`` takes the
three from :func:`realization`. A constant fault's steady state does not depend on the delay (at a constant
command every difference term vanishes), which is what keeps the loop's deviation coordinates exact.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["lag_span", "lag_intervals", "lag_point", "lag_realization", "lagged_matrices", "curve_of", "MAX_LAG_PARTS"]

# each whole-sample part the interval spans multiplies the certificate's vertices by its own polytope's count
# (up to 2n): 3 parts on a 4-state aircraft is 512 vertices, minutes of LMI solving; 3 is the practical limit
MAX_LAG_PARTS = 3


def curve_of(A_c: np.ndarray, B_c: np.ndarray, h: float) -> Callable[[float], np.ndarray]:
    """``a -> G(a) = int_a^h e^{A_c (h - s)} ds B_c`` for ``a`` in ``[0, h]``: the ``B0`` of a delay ``a``."""
    from monitor.model.discretize import integral_expm

    def curve(a: float) -> np.ndarray:
        G: np.ndarray = integral_expm(A_c, h - float(a))[1] @ B_c
        return G

    return curve


def lag_span(h: float, tau_min: float, tau_max: float) -> tuple[int, int]:
    """``(first, last)``: the whole samples of the shortest and the longest delay (``floor(tau / h)``).

    A tiny tolerance keeps a bound written as an exact multiple of h (``0.1`` at ``h = 0.05``) on the
    multiple despite its binary rounding.
    """
    first = int(math.floor(tau_min / h + 1e-9))
    last = int(math.floor(tau_max / h + 1e-9))
    return first, last


def lag_intervals(h: float, tau_min: float, tau_max: float) -> list[tuple[float, float]]:
    """``[lo_j, hi_j]`` for ``j = first..last``: where in its interval ``u(k-j)`` (or a newer command) can act."""
    first, last = lag_span(h, tau_min, tau_max)

    def clip(t: float) -> float:
        return min(max(t, 0.0), h)

    return [(clip(tau_min - j * h), clip(tau_max - j * h)) for j in range(first, last + 1)]


def lag_point(curve: Callable[[float], np.ndarray], h: float, tau_min: float, tau_max: float, tau: float) -> np.ndarray:
    """The stacked ``[G(a_first); ...; G(a_last)]`` of a *constant* delay ``tau`` (``a_j = clip(tau - j h)``).

    ``curve(a)`` is ``G(a)``. A constant delay is one admissible pattern among many; the polytope holds all.
    """
    first, last = lag_span(h, tau_min, tau_max)
    return np.vstack([curve(min(max(tau - j * h, 0.0), h)) for j in range(first, last + 1)])


def lag_realization(
    point: np.ndarray, A: np.ndarray, G0: np.ndarray, first: int, last: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B0, B1)`` of the lagged plant at one point ``[G(a_first); ...; G(a_last)]`` (see the module docstring).

    ``A`` and ``G0 = G(0)`` are the sampled plant's own; the result acts on ``[x; u(k-2); ...; u(k-last-1)]``
    with inputs ``u(k)`` (B0) and ``u(k-1)`` (B1).
    """
    n, m = G0.shape
    parts = {j: point[(j - first) * n : (j - first + 1) * n] for j in range(first, last + 1)}
    zero = np.zeros((n, m))

    def coefficient(j: int) -> np.ndarray:  # of u(k-j) in x(k+1)
        c: np.ndarray = parts.get(j, zero) - parts.get(j - 1, zero)
        return c + G0 if j == last + 1 else c

    n_a = n + m * last
    A_a = np.zeros((n_a, n_a))
    A_a[:n, :n] = A
    for j in range(2, last + 2):  # u(k-j) sits in history slot j - 1
        A_a[:n, n + (j - 2) * m : n + (j - 1) * m] = coefficient(j)
    for s in range(1, last):  # slot s+1 takes slot s
        A_a[n + s * m : n + (s + 1) * m, n + (s - 1) * m : n + s * m] = np.eye(m)
    B0 = np.zeros((n_a, m))
    B0[:n] = coefficient(0)
    B1 = np.zeros((n_a, m))
    B1[:n] = coefficient(1)
    if last >= 1:
        B1[n : n + m] = np.eye(m)  # u(k-2) at k+1 is u(k-1) now
    return A_a, B0, B1


def lagged_matrices(
    C: np.ndarray, Df: np.ndarray, Dd: np.ndarray, m: int, last: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``C``, ``Df``, ``Dd`` of the lagged plant: the history slots are neither measured nor disturbed."""
    extra = m * last
    return (
        np.hstack([C, np.zeros((C.shape[0], extra))]),
        np.vstack([Df, np.zeros((extra, Df.shape[1]))]),
        np.vstack([Dd, np.zeros((extra, Dd.shape[1]))]),
    )
