"""``hinf_norms`` (Schur form, back substitution over the frequency grid) against a plain evaluation.

Why: every design's search and ``verify`` lean on it; the reference here solves ``(zI - A) X = B`` with LAPACK
at each frequency of a dense grid and takes the largest singular value by SVD, on random stable systems and on defective
ones (a nilpotent block, as a deadbeat observer has), perturbed at 1e-9 as another machine would round.
"""

from __future__ import annotations

import numpy as np

from monitor.model.norms import hinf_norm, hinf_norms


def _reference(A: np.ndarray, B: np.ndarray, C: np.ndarray, points: int = 20001) -> float:
    """max over a dense grid of sigma_max(C (e^{jw} I - A)^-1 B): a LAPACK solve and an SVD per frequency."""
    z = np.exp(1j * np.linspace(0.0, np.pi, points))
    X = np.linalg.solve(z[:, None, None] * np.eye(A.shape[0]) - A, np.broadcast_to(B, (z.size, *B.shape)))
    return float(np.max(np.linalg.svd(C @ X, compute_uv=False)[:, 0]))


def _systems(rng: np.random.Generator):
    for trial in range(12):
        n, m, l = int(rng.integers(1, 9)), int(rng.integers(1, 4)), int(rng.integers(1, 5))
        A = rng.normal(size=(n, n))
        A /= np.max(np.abs(np.linalg.eigvals(A))) * rng.uniform(1.1, 2.0)
        if trial % 3 == 0 and n > 1:  # defective: Q N Q' with N nilpotent
            Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
            A = 0.9 * Q @ (np.diag(np.ones(n - 1), 1) * rng.uniform(0.5, 2.0)) @ Q.T
        yield A, rng.normal(size=(n, m)), [rng.normal(size=(1, n)), rng.normal(size=(l, n))]


def test_hinf_norms_agree_with_a_per_frequency_evaluation_also_perturbed():
    rng = np.random.default_rng(5)
    for A, B, outputs in _systems(rng):
        fast = hinf_norms(A, B, outputs)
        shaken = hinf_norms(A * (1 + 1e-9 * rng.standard_normal(A.shape)), B, outputs)
        for C, value, value_shaken in zip(outputs, fast, shaken, strict=True):
            reference = _reference(A, B, C)
            # the refined peak is at least the dense grid's and within its resolution above it
            assert reference * (1 - 1e-9) <= value <= reference * (1 + 1e-3), (value, reference)
            assert abs(value_shaken - value) <= 1e-6 * value


def test_an_unstable_system_has_no_finite_norm():
    assert hinf_norm(np.array([[1.01]]), np.array([[1.0]]), np.array([[1.0]])) == float("inf")
