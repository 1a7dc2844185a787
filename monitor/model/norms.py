"""Norms the designs and the checks share: quadratic norms ``||x||_P = sqrt(x' P x)`` and the H-infinity norm.

Why one module: ``verify --max-losses`` and ``threshold`` both turn a candidate P (from an LMI, a Lyapunov
equation or a file) into a proof by recomputing, in numpy, how much each matrix stretches vectors in that
norm; doing it in one place means one definition of "P is a norm" and of the induced norm. The H-infinity
norm (a frequency sweep) is here and not in ``verify`` so that the designs, which use it as a search proxy,
import a norm and not the check that is meant to judge them independently.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

__all__ = ["norm_factor", "induced_norms", "dual_norms", "contraction", "hinf_norm", "hinf_norms"]


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
    norms: np.ndarray = np.linalg.norm(R @ np.asarray(mats) @ np.linalg.inv(R), 2, axis=(-2, -1))
    return norms


def dual_norms(rows: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``||r||_* = sqrt(r P^-1 r')``, the dual of ``||x||_P``, row by row: ``|r x| <= ||r||_* ||x||_P``."""
    norms: np.ndarray = np.linalg.norm(np.linalg.solve(R.T, np.atleast_2d(rows).T), axis=0)
    return norms


def contraction(P: np.ndarray, steps: list[np.ndarray], depth: int = 1) -> float:
    """``max ||product||_P ** (1/depth)`` over every product of ``depth`` (1 or 2) macro-steps; inf when P is no norm.

    < 1 proves that every product of the steps (in any order, any convex combination) converges.
    """
    R = norm_factor(P)
    if R is None:
        return float("inf")
    mats = np.array(steps)
    if depth == 2:
        mats = np.einsum("iab,jbc->ijac", mats, mats).reshape(-1, *mats.shape[1:])
    factor: float = float(np.max(induced_norms(R, mats))) ** (1.0 / depth)
    return factor


def hinf_norm(A: np.ndarray, B: np.ndarray, C: np.ndarray, points: int = 2048) -> float:
    """``sup_w sigma_max(C (e^{jw} I - A)^-1 B)`` of a stable discrete system; inf when unstable."""
    return hinf_norms(A, B, [C], points)[0]


def hinf_norms(A: np.ndarray, B: np.ndarray, outputs: list[np.ndarray], points: int = 2048) -> list[float]:
    """:func:`hinf_norm` for several output matrices of one ``(A, B)``: the resolvent is solved once per frequency.

    A dense sweep (``points`` on ``[0, pi]`` plus 200 log-spaced low frequencies, where slow modes peak),
    then the peak refined by zooming: each level evaluates 17 frequencies in one batched solve and keeps
    the two grid steps around the best one (1/8 of the bracket), so 7 levels locate it to about 1e-7 of a
    sweep step. Batched calls instead of a scalar search's ~30 single-frequency solves: the design searches
    call this thousands of times.
    """
    T, Z = scipy.linalg.schur(np.asarray(A, dtype=complex), output="complex")
    poles = np.diag(T)
    if np.max(np.abs(poles)) >= 1.0:
        return [float("inf")] * len(outputs)
    n = A.shape[0]
    Bt = Z.conj().T @ B
    upper = [T[i, i + 1 :] for i in range(n)]

    def resolvent(omega: np.ndarray) -> np.ndarray:
        """``(e^{jw} I - A)^-1 B`` in Schur coordinates (times Z^H): a triangular solve, vectorised over w.

        Why Schur and not ``np.linalg.solve`` per frequency: back substitution on the triangular factor costs
        n vector operations over the whole grid instead of one LAPACK call per frequency (about 10x faster
        for the loops here), and unlike an eigendecomposition it stays exact for defective matrices (a
        deadbeat observer's nilpotent block).
        """
        z = np.exp(1j * np.atleast_1d(omega))
        X = np.empty((n, z.size, Bt.shape[1]), dtype=complex)  # state index first: X[i + 1:] is contiguous
        flat = X.reshape(n, -1)  # a view: one matrix-vector product per row (tensordot's reshapes cost 3x)
        for i in range(n - 1, -1, -1):
            acc = (
                Bt[i] + (upper[i] @ flat[i + 1 :]).reshape(z.size, -1)
                if i < n - 1
                else np.broadcast_to(Bt[i], (z.size, Bt.shape[1]))
            )
            X[i] = acc / (z - poles[i])[:, None]
        return X

    rotated = [np.asarray(C) @ Z for C in outputs]

    def gain(C: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Largest singular value of ``C R`` per frequency, in closed form for one or two columns or rows."""
        G = np.tensordot(C, R, axes=(1, 0)).transpose(1, 0, 2)  # (frequencies, outputs, inputs)
        if G.shape[1] < G.shape[2]:
            G = G.conj().transpose(0, 2, 1)  # same singular values, fewer columns
        sigma: np.ndarray
        if G.shape[2] == 1:
            sigma = np.sqrt(np.sum(np.abs(G[:, :, 0]) ** 2, axis=1))
            return sigma
        if G.shape[2] == 2:  # the largest eigenvalue of the 2 x 2 Gram matrix G^H G
            a = np.sum(np.abs(G[:, :, 0]) ** 2, axis=1)
            d = np.sum(np.abs(G[:, :, 1]) ** 2, axis=1)
            b = np.sum(G[:, :, 0].conj() * G[:, :, 1], axis=1)
            sigma = np.sqrt(0.5 * (a + d) + np.sqrt(0.25 * (a - d) ** 2 + np.abs(b) ** 2))
            return sigma
        return np.linalg.svd(G, compute_uv=False)[:, 0]

    omegas = np.concatenate([np.linspace(0.0, np.pi, points), np.geomspace(1e-5, 1e-1, 200)])
    sweep = resolvent(omegas)
    step = np.pi / (points - 1)
    norms = []
    for C in rotated:
        values = gain(C, sweep)
        i = int(np.argmax(values))
        best = float(values[i])
        lo, hi = max(omegas[i] - step, 0.0), min(omegas[i] + step, np.pi)
        for _ in range(7):
            grid = np.linspace(lo, hi, 17)
            level = gain(C, resolvent(grid))
            j = int(np.argmax(level))
            best = max(best, float(level[j]))
            width = (hi - lo) / 16
            lo, hi = max(grid[j] - width, 0.0), min(grid[j] + width, np.pi)
        norms.append(best)
    return norms
