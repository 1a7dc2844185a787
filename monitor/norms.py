"""Quadratic norms ``||x||_P = sqrt(x' P x)``: the one piece of numpy every stability and bound proof here shares.

Why one module: ``verify --max-losses`` and ``threshold`` both turn a candidate P (from an LMI, a Lyapunov
equation or a file) into a proof by recomputing, in numpy, how much each matrix stretches vectors in that
norm; doing it in one place means one definition of "P is a norm" and of the induced norm.
"""

from __future__ import annotations

import numpy as np

__all__ = ["norm_factor", "induced_norms", "dual_norms"]


def norm_factor(P: np.ndarray | None) -> np.ndarray | None:
    """``R`` with ``P = R' R`` (so ``||x||_P = ||R x||``) from P's symmetric part; None when P is no norm."""
    if P is None or not np.all(np.isfinite(P)):
        return None
    try:
        return np.linalg.cholesky(0.5 * (P + P.T)).T
    except np.linalg.LinAlgError:
        return None


def induced_norms(R: np.ndarray, mats: np.ndarray) -> np.ndarray:
    """``||M||_P = ||R M R^-1||_2`` for each matrix of ``mats`` (shape ``(..., N, N)``)."""
    return np.linalg.norm(R @ np.asarray(mats) @ np.linalg.inv(R), 2, axis=(-2, -1))


def dual_norms(rows: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``||r||_* = sqrt(r P^-1 r')``, the dual of ``||x||_P``, row by row: ``|r x| <= ||r||_* ||x||_P``."""
    return np.linalg.norm(np.linalg.solve(R.T, np.atleast_2d(rows).T), axis=0)
