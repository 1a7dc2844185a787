"""An independent check of any gains on the real closed loop, sharing nothing with the LMI designs.

It rebuilds the loop with the ``u(k-1)`` state (``monitor.model.closed_loop``) from the plant and the gains alone
and reports:

* ``rho_max``/``tau_worst``: the largest spectral radius over a dense grid of constant delays;
* ``rho_time_varying``: the growth rate of long products of loop matrices with the delay switching at
  random (and between the interval's ends) every sample, a lower bound of the joint spectral radius:
  > 1 means some delay sequence makes the loop diverge even if every constant delay is fine;
* ``hinf_ef``/``hinf_y``: the worst over delays of the H-infinity norm from ``w = [d; Delta f]`` to ``e_f``
  and to ``y~``, from a dense frequency sweep refined near the peak (no LMI, no python-control);
* ``certificate_valid``: when the gains file carries Lyapunov matrices and polytope vertices, the
  Bounded Real Lemma re-checked in numpy at every vertex, plus a check that every ``B0(tau)`` of the
  grid lies inside the polytope (a linear program per point).

Past one sample (a plant whose ``tau_max >= h``, ``monitor.model.long_delay``) the points checked are the
constant delays of the grid plus arrival patterns in which each whole-sample part sits anywhere in its window
independently (the windows' corners first): the switching a varying delay causes. They join the
time-varying growth and the certificate's containment check.

``stable`` is true only when ``rho_max < 1`` and ``rho_time_varying < 1``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.optimize import linprog

from monitor.model.closed_loop import Gains, LoopMatrices, closed_loop, steady_state
from monitor.model.delay_model import b0_of_tau, lag_curve, point_size, tau_grid
from monitor.model.long_delay import lag_intervals
from monitor.model.norms import hinf_norms
from monitor.model.plant import Plant

__all__ = ["Verdict", "verify_gains", "points_inside"]


@dataclass
class Verdict:
    stable: bool
    rho_max: float
    tau_worst: float
    rho_time_varying: float
    hinf_ef: float
    hinf_y: float
    tau_hinf_worst: float
    fault_leak: float | None
    certificate_valid: bool | None
    certificate_detail: str
    gamma_e_claimed: float | None = None
    gamma_z_claimed: float | None = None
    bound_holds: bool | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _points(plant: Plant, taus: np.ndarray, seed: int, mixed: int = 40) -> list[np.ndarray]:
    """The uncertain points checked: every constant delay of the grid and, past one sample, ``mixed`` arrival
    patterns where each whole-sample part sits anywhere in its window independently (a delay that changes
    from one command to the next): constant delays alone would never show the loop switching between parts."""
    points = [b0_of_tau(plant, float(t)) for t in taus]
    if plant.lags is None:
        return points
    curve = lag_curve(plant.lags.base)
    windows = lag_intervals(plant.h, plant.tau_min, plant.tau_max)
    rng = np.random.default_rng([seed, 0x1A6])
    corners = [[lo, hi] for lo, hi in windows]
    for i in range(mixed):  # the windows' corners first (the extreme switches), then random interior points
        if i < 2 ** len(windows):
            a = [c[(i >> b) & 1] for b, c in enumerate(corners)]
        else:
            a = [rng.uniform(lo, hi) for lo, hi in windows]
        points.append(np.vstack([curve(float(x)) for x in a]))
    return points


def _loops(
    plant: Plant, gains: Gains, points: list[np.ndarray], steady: tuple[np.ndarray, np.ndarray]
) -> list[LoopMatrices]:
    return [closed_loop(plant, gains, point, steady=steady) for point in points]


def _growth_rate(mats: list[np.ndarray], rng: np.random.Generator, steps: int = 3000, last: int | None = None) -> float:
    """Largest per-step growth of ``||A(k) ... A(1)||`` over a few switching patterns (renormalised).

    Measured over the second half of the product only, ``(||P_T|| / ||P_{T/2}||)^(2/T)``: a loop with a
    slow mode (an aircraft's phugoid at h = 0.02 s has an eigenvalue of 0.9999) and a large transient first
    would otherwise count its transient as growth (measured: 1.0007 for a loop whose certificate proves it
    stable), while after T/2 samples only the asymptotic rate is left.
    """
    N = mats[0].shape[0]
    end = len(mats) - 1 if last is None else last  # the index of tau_max (mixed arrival patterns follow it)
    patterns = [
        rng.integers(0, len(mats), steps),  # i.i.d. delays over the grid
        np.arange(steps) % 2 * end,  # alternate the two ends of the interval
        rng.integers(0, 2, steps) * end,  # random ends
    ]
    worst = 0.0
    half = steps // 2
    for pattern in patterns:
        V = np.eye(N)
        log_growth = 0.0
        for i, j in enumerate(pattern):
            V = mats[j] @ V
            s = np.linalg.norm(V, 2)
            if not np.isfinite(s) or s == 0.0:
                break
            if i >= half:
                log_growth += np.log(s)
            V /= s
        worst = max(worst, float(np.exp(log_growth / (steps - half))))
    return worst


def _lp_inside(point: np.ndarray, vertices: np.ndarray) -> bool:
    """``point`` is a convex combination of the rows of ``vertices``: a feasibility linear program (exact)."""
    k = len(vertices)
    res = linprog(
        np.zeros(k),
        A_eq=np.vstack([vertices.T, np.ones((1, k))]),
        b_eq=np.append(point.ravel(), 1.0),
        bounds=[(0, None)] * k,
        method="highs",
    )
    return bool(res.status == 0)


def points_inside(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """For each row of ``points``: does it lie in the convex hull of the rows of ``vertices``?

    Why not a linear program per point alone: each costs ~8 ms through scipy, and a certificate is checked against
    hundreds of delays. The hull's facets (Qhull, exact for the vertices given) decide every point that is clearly
    inside or outside in one product; a point within 1e-9 (relative) of a facet, and every point when no hull can
    be built (flat vertices, or more than 8 dimensions), gets the linear program.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    verts = np.atleast_2d(np.asarray(vertices, dtype=float))
    verdict = np.zeros(len(pts), dtype=bool)
    undecided = np.ones(len(pts), dtype=bool)
    k, dim = verts.shape
    if 2 <= dim <= 8 and k > dim:
        from scipy.spatial import ConvexHull, QhullError

        try:
            hull = ConvexHull(verts)
        except (QhullError, ValueError):
            hull = None
        if hull is not None:
            tol = 1e-9 * max(1.0, float(np.max(np.abs(verts))))
            distance = (pts @ hull.equations[:, :-1].T + hull.equations[:, -1]).max(axis=1)  # <= 0: inside
            verdict = distance < -tol
            undecided = np.abs(distance) <= tol
    for i in np.flatnonzero(undecided):
        verdict[i] = _lp_inside(pts[i], verts)
    return verdict


def _check_certificate(
    plant: Plant,
    gains: Gains,
    certificate: dict[str, np.ndarray],
    gamma_e: float | None,
    gamma_z: float | None,
    steady: tuple[np.ndarray, np.ndarray],
    points: list[np.ndarray],
) -> tuple[bool | None, str]:
    """Re-check a polytopic certificate: containment of every point checked, then the BRL at every vertex."""
    if not {"P", "Q", "vertices"} <= set(certificate) or gamma_e is None or gamma_z is None:
        return None, "no polytopic certificate in the gains file"
    P, Q, vertices = certificate["P"], certificate["Q"], certificate["vertices"]
    N = 2 * plant.n + plant.q + plant.m
    if P.shape != (N, N) or Q.shape != (N, N) or vertices.shape[1] != point_size(plant):
        return False, "certificate matrices do not fit the real closed loop of this plant"
    inside = points_inside(np.array([point.ravel() for point in points]), vertices)
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        return (
            False,
            f"uncertain point {i} (of {len(points)}; the first are the constant delays) lies outside the "
            "certificate's polytope",
        )
    if np.min(np.linalg.eigvalsh(P)) <= 0 or np.min(np.linalg.eigvalsh(Q)) <= 0:
        return False, "certificate matrices are not positive definite"
    for v in vertices:
        loop = closed_loop(plant, gains, v.reshape(-1, plant.m), steady=steady)
        for X, C, gamma in ((P, loop.C_ef, gamma_e), (Q, loop.C_y, gamma_z)):
            A, B = loop.A, loop.B
            brl = np.block(
                [[A.T @ X @ A - X + C.T @ C, A.T @ X @ B], [B.T @ X @ A, B.T @ X @ B - gamma**2 * np.eye(B.shape[1])]]
            )
            top = float(np.max(np.linalg.eigvalsh(0.5 * (brl + brl.T))))
            if top >= 0.0:
                return False, f"Bounded Real Lemma fails at a vertex (largest eigenvalue {top:.3g})"
    return (
        True,
        f"common P, Q valid at all {len(vertices)} vertices; polytope contains the {len(points)} points checked",
    )


def verify_gains(
    plant: Plant,
    gains: Gains,
    certificate: dict[str, np.ndarray] | None = None,
    gamma_e: float | None = None,
    gamma_z: float | None = None,
    grid_points: int = 201,
    seed: int = 0,
) -> Verdict:
    """The verdict on ``gains`` for every delay in the plant's interval (see the module docstring)."""
    gains.check_shapes(plant)
    taus = tau_grid(plant, grid_points)
    try:
        steady = steady_state(plant, gains)
        S_x = steady[0]
        fault_leak: float | None = float(np.linalg.norm(plant.C @ S_x, 2))
    except ValueError:
        steady = (np.zeros((plant.n, plant.q)), np.zeros((plant.m, plant.q)))
        fault_leak = None  # a pole at 1: a constant fault has no steady state
    points = _points(plant, taus, seed)
    loops = _loops(plant, gains, points, steady)
    radii = np.array([np.max(np.abs(np.linalg.eigvals(lp.A))) for lp in loops[: len(taus)]])
    i_worst = int(np.argmax(radii))
    rho_tv = _growth_rate([lp.A for lp in loops], np.random.default_rng(seed), last=len(taus) - 1)
    hinf_taus = np.unique(np.linspace(0, len(taus) - 1, 41).astype(int))
    # both outputs from one frequency sweep per delay (the resolvent is shared; the same figures as two sweeps)
    both = [hinf_norms(loops[i].A, loops[i].B, [loops[i].C_ef, loops[i].C_y], points=2048) for i in hinf_taus]
    ef = [b[0] for b in both]
    yy = [b[1] for b in both]
    j_worst = int(np.argmax(ef))
    cert_ok, detail = (None, "no certificate given")
    if certificate:
        cert_ok, detail = _check_certificate(plant, gains, certificate, gamma_e, gamma_z, steady, points)
    stable = bool(radii[i_worst] < 1.0 and rho_tv < 1.0)
    bound_holds = None
    if gamma_e is not None and gamma_z is not None:
        bound_holds = bool(stable and max(ef) <= gamma_e * (1 + 1e-6) and max(yy) <= gamma_z * (1 + 1e-6))
    return Verdict(
        stable=stable,
        rho_max=float(radii[i_worst]),
        tau_worst=float(taus[i_worst]),
        rho_time_varying=rho_tv,
        hinf_ef=float(max(ef)),
        hinf_y=float(max(yy)),
        tau_hinf_worst=float(taus[hinf_taus[j_worst]]),
        fault_leak=fault_leak,
        certificate_valid=cert_ok,
        certificate_detail=detail,
        gamma_e_claimed=gamma_e,
        gamma_z_claimed=gamma_z,
        bound_holds=bound_holds,
    )
