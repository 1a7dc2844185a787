"""The one LMI block every design here uses: discrete H-infinity with a slack matrix (the paper's (16)/(17)).

    [[X - G - G^T, G^T A, G^T B, 0], [A^T G, -X, 0, C^T], [B^T G, 0, -g I, 0], [0, C, 0, -I]] < 0

implies ``A^T X A - X + C^T C + ... < 0`` with the same X, i.e. stability and an H-infinity bound
``sqrt(g)`` from the input of B to the output C. ``GA`` and ``GB`` are passed in already multiplied
(each method has its own change of variables that makes them affine).
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from monitor.design.solve import EPS, most_positive_eigenvalue

__all__ = ["hinf_slack_lmi", "brl_block", "brl_margin"]


def hinf_slack_lmi(
    X: cp.Expression, G: cp.Expression, GA: cp.Expression, GB: cp.Expression, C: np.ndarray, g: cp.Expression | float
) -> cp.Constraint:
    """The constraint above, symmetrised explicitly (cvxpy wants a symmetric expression)."""
    N = C.shape[1]
    k = C.shape[0]
    nw = GB.shape[1]
    block = cp.bmat(
        [
            [X - G - G.T, GA, GB, np.zeros((N, k))],
            [GA.T, -X, np.zeros((N, nw)), C.T],
            [GB.T, np.zeros((nw, N)), -g * np.eye(nw), np.zeros((nw, k))],
            [np.zeros((k, N)), C, np.zeros((k, nw)), -np.eye(k)],
        ]
    )
    size = 2 * N + nw + k
    constraint: cp.Constraint = 0.5 * (block + block.T) << -EPS * np.eye(size)
    return constraint


def brl_block(X: cp.Expression, A: np.ndarray, B: np.ndarray, C: np.ndarray, g: cp.Expression) -> cp.Constraint:
    """The discrete Bounded Real Lemma in its compact form, affine in X and g for fixed (A, B):

        [[A^T X A - X, A^T X B, C^T], [B^T X A, B^T X B - g I, 0], [C, 0, -I]] < 0.

    Why this form and not the expanded ``[[-X, 0, A^T X, C^T], ..., [X A, X B, -X, 0], ...]``: both are affine
    in X and equivalent (a Schur complement), but this block has ``N + nw + k`` rows instead of ``2 N + nw + k``,
    and an interior-point step's cost grows with the square of each cone's size. Measured on 16 vertices of a
    14-state loop: 2.2 s instead of 14.8 s, the same optimum; it made a 64-vertex certificate (a delay past one
    sample on a 4-state aircraft) take seconds instead of minutes. It is also exactly the matrix ``verify``
    and ``brl_margin`` re-check.
    """
    N, nw, k = C.shape[1], B.shape[1], C.shape[0]
    AXA, AXB, BXB = A.T @ X @ A, A.T @ X @ B, B.T @ X @ B
    block = cp.bmat(
        [
            [AXA - X, AXB, C.T],
            [AXB.T, BXB - g * np.eye(nw), np.zeros((nw, k))],
            [C, np.zeros((k, nw)), -np.eye(k)],
        ]
    )
    constraint: cp.Constraint = 0.5 * (block + block.T) << -EPS * np.eye(N + nw + k)
    return constraint


def brl_margin(X: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray, g: float) -> float:
    """What either LMI form claims, re-evaluated in numpy: the margin of ``X > 0`` and of the Bounded Real Lemma

        [[A^T X A - X, A^T X B, C^T], [B^T X A, B^T X B - g I, 0], [C, 0, -I]] < 0

    for the closed loop ``(A, B, C)`` built from the *recovered* gains. Both the slack form above and the
    plain form of ``monitor.design.certificate`` posed with ``<= -EPS I`` imply this matrix ``<= -EPS I``
    (a congruence with a matrix whose Gram is ``>= I``), and ``X >= EPS I``; so a point the solver really
    solved has margin ``>= EPS``, and stability plus the bound ``sqrt(g)`` follow from any positive margin.
    """
    nw, k = B.shape[1], C.shape[0]
    M = np.block(
        [
            [A.T @ X @ A - X, A.T @ X @ B, C.T],
            [B.T @ X @ A, B.T @ X @ B - g * np.eye(nw), np.zeros((nw, k))],
            [C, np.zeros((k, nw)), -np.eye(k)],
        ]
    )
    return min(-most_positive_eigenvalue(-X), -most_positive_eigenvalue(M))
