"""An independent check of gains over an envelope: every point as ``verify`` judges one plant, the common certificate
recomputed from the matrices, and the switched loop simulated under the fastest switching.

Nothing here comes from the design's code: the loops are rebuilt from each point's plant and gains
(``monitor.model.closed_loop``), and

* **per point**: :func:`monitor.checks.verify.verify_gains` (spectral radius over a dense delay grid, growth under
  time-varying delays, H-infinity norms, the point's own certificate when the file carries one);
* **the common certificate**: ``P`` symmetric and positive definite by its eigenvalues; for every point and every
  vertex of the point's polytope (as the gains file lists them), the stability LMI ``A' P A - P`` and the Bounded
  Real Lemma ``[[A' P A - P + C' C, A' P B], [B' P A, B' P B - gamma^2 I]]`` negative definite by their
  eigenvalues; and every ``B0(tau)`` of a dense delay grid of each point inside that point's polytope (a linear
  program per delay). Then any switching among the points, at any rate and with any delays, is stable with the
  bound gamma on ``w -> e_f``;
* **the switched loop**: products of the points' loop matrices, a different random point every sample (the
  fastest switching) at a random delay of the interval, for a few thousand samples from every initial state at
  once (the product's 2-norm): ``switching_sim_max`` is the largest amplification of the initial state seen,
  ``switching_sim_growth`` the per-sample growth over the second half of the run (< 1: bounded and decaying).
  A simulation proves nothing; it shows divergence when there is some, which a missing certificate cannot.

``stable`` holds only when every point is stable, the common certificate holds and the simulation is bounded.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.checks.verify import Verdict, points_inside, verify_gains
from monitor.model.closed_loop import Gains, closed_loop, steady_state
from monitor.model.delay_model import b0_of_tau, point_size, tau_grid
from monitor.model.envelope import Envelope
from monitor.model.plant import Plant

__all__ = [
    "CommonClaim",
    "PointClaim",
    "PointCheck",
    "EnvelopeVerdict",
    "verify_envelope",
    "check_common",
    "switching_growth",
]

SIM_SAMPLES = 3000
SIM_RUNS = 4
SIM_DELAYS = 21  # delays per point the simulation draws from (both ends of the interval included)
CONTAINMENT_GRID = 201  # delays per point whose B0(tau) must lie in the point's polytope


@dataclass
class PointClaim:
    """What a gains file claims for one point: its own certificate (P, Q, vertices) and bounds."""

    certificate: dict[str, np.ndarray] = field(default_factory=dict)
    gamma_e: float | None = None
    gamma_z: float | None = None


@dataclass
class CommonClaim:
    """The envelope's certificate as the gains file records it."""

    P: np.ndarray
    gamma: float
    vertices: dict[str, np.ndarray]  # point -> one raveled uncertain point per row


@dataclass
class PointCheck:
    name: str
    verdict: Verdict

    def as_dict(self) -> dict[str, Any]:
        v = self.verdict
        return {
            "name": self.name,
            "stable": v.stable,
            "rho_max": v.rho_max,
            "hinf_ef": v.hinf_ef,
            "rho_time_varying": v.rho_time_varying,
            "hinf_y": v.hinf_y,
            "certificate_valid": v.certificate_valid,
            "bound_holds": v.bound_holds,
        }


@dataclass
class EnvelopeVerdict:
    stable: bool
    points: list[PointCheck]
    common_certificate: bool
    gamma_common: float | None
    common_detail: str
    switching_sim_max: float
    switching_sim_growth: float
    switching_bounded: bool
    switching_samples: int

    def as_dict(self) -> dict[str, Any]:
        return {
            "stable": self.stable,
            "points": [p.as_dict() for p in self.points],
            "common_certificate": self.common_certificate,
            "gamma_common": self.gamma_common,
            "switching_sim_max": self.switching_sim_max,
            "common_detail": self.common_detail,
            "switching_sim_growth": self.switching_sim_growth,
            "switching_bounded": self.switching_bounded,
            "switching_samples": self.switching_samples,
        }


def _top(M: np.ndarray) -> float:
    """Largest eigenvalue of the symmetric part: the matrix is negative definite exactly when this is < 0."""
    return float(np.max(np.linalg.eigvalsh(0.5 * (M + M.T))))


def check_common(envelope: Envelope, gains: Mapping[str, Gains], claim: CommonClaim | None) -> tuple[bool, str]:
    """The common certificate recomputed from the matrices (see the module docstring): (holds, why)."""
    if claim is None:
        return False, "no common certificate in the gains file"
    first = envelope.first
    N = 2 * first.n + first.q + first.m
    P = np.asarray(claim.P, dtype=float)
    if P.shape != (N, N) or not np.all(np.isfinite(P)):
        return False, f"P must be a finite {N} x {N} matrix for this envelope's loop, got {P.shape[0]} x {P.shape[1]}"
    if np.max(np.abs(P - P.T)) > 1e-9 * max(1.0, float(np.max(np.abs(P)))):
        return False, "P is not symmetric"
    low = float(np.min(np.linalg.eigvalsh(P)))
    if low <= 0.0:
        return False, f"P is not positive definite (smallest eigenvalue {low:.3g})"
    if not (np.isfinite(claim.gamma) and claim.gamma > 0):
        return False, f"gamma must be a positive number, got {claim.gamma}"
    g2 = claim.gamma**2
    count = 0
    for point in envelope.points:
        plant = point.plant
        vertices = claim.vertices.get(point.name)
        if vertices is None or vertices.ndim != 2 or vertices.shape[1] != point_size(plant) or len(vertices) == 0:
            return False, f"no vertices of point '{point.name}' that fit its plant"
        taus = tau_grid(plant, CONTAINMENT_GRID)
        inside = points_inside(np.array([b0_of_tau(plant, float(t)).ravel() for t in taus]), vertices)
        if not inside.all():
            tau = float(taus[~inside][0])
            return False, f"B0(tau = {tau:.4g}) of point '{point.name}' lies outside the vertices the file lists for it"
        steady = steady_state(plant, gains[point.name])
        for i, v in enumerate(vertices):
            loop = closed_loop(plant, gains[point.name], v.reshape(-1, plant.m), steady=steady)
            A, B, C = loop.A, loop.B, loop.C_ef
            stability = _top(A.T @ P @ A - P)
            if stability >= 0.0:
                return (
                    False,
                    f"A' P A - P is not negative definite at point '{point.name}', vertex {i} ({stability:.3g})",
                )
            brl = np.block(
                [[A.T @ P @ A - P + C.T @ C, A.T @ P @ B], [B.T @ P @ A, B.T @ P @ B - g2 * np.eye(B.shape[1])]]
            )
            top = _top(brl)
            if top >= 0.0:
                return (
                    False,
                    f"the bounded-real LMI fails at point '{point.name}', vertex {i} (largest eigenvalue {top:.3g})",
                )
            count += 1
    return True, (
        f"one P > 0 for all {len(envelope.points)} points at their {count} delay vertices: stability and the bound "
        f"{claim.gamma:.4g} on w -> e_f hold under any switching among the points; every B0(tau) of a "
        f"{CONTAINMENT_GRID}-delay grid lies in its point's polytope"
    )


def _point_matrices(plant: Plant, gains: Gains) -> list[np.ndarray]:
    steady = steady_state(plant, gains)
    return [closed_loop(plant, gains, b0_of_tau(plant, float(t)), steady=steady).A for t in tau_grid(plant, SIM_DELAYS)]


def switching_growth(
    mats: list[list[np.ndarray]], samples: int = SIM_SAMPLES, runs: int = SIM_RUNS, seed: int = 0
) -> tuple[float, float]:
    """``(max amplification, growth per sample over the second half)`` of products ``A(k) ... A(1)``, where each
    sample takes a point other than the last one's (two points: they alternate) at a random delay of its grid."""
    rng = np.random.default_rng([seed, 0xE1])
    N = mats[0][0].shape[0]
    peak, growth = 0.0, 0.0
    half = samples // 2
    for _ in range(runs):
        V = np.eye(N)
        log_norm = 0.0  # log of the unnormalised product's norm
        log_half = 0.0
        log_peak = 0.0
        point = int(rng.integers(len(mats)))
        for k in range(samples):
            if k and len(mats) > 1:
                step = int(rng.integers(1, len(mats)))  # any other point
                point = (point + step) % len(mats)
            A = mats[point][int(rng.integers(len(mats[point])))]
            V = A @ V
            s = float(np.linalg.norm(V, 2))
            if not np.isfinite(s) or s == 0.0:
                if s == 0.0:  # the product vanished: nothing grows
                    log_norm = -np.inf
                    break
                return float("inf"), float("inf")
            log_norm += np.log(s)
            V /= s
            log_peak = max(log_peak, log_norm)
            if k == half - 1:
                log_half = log_norm
        peak = max(peak, float(np.exp(min(log_peak, 700.0))))
        rate = 0.0 if not np.isfinite(log_norm) else float(np.exp((log_norm - log_half) / (samples - half)))
        growth = max(growth, rate)
    return peak, growth


def verify_envelope(
    envelope: Envelope,
    gains: Mapping[str, Gains],
    claims: Mapping[str, PointClaim] | None = None,
    common: CommonClaim | None = None,
    samples: int = SIM_SAMPLES,
    seed: int = 0,
) -> EnvelopeVerdict:
    """The verdict on per-point ``gains`` over the envelope (see the module docstring)."""
    claims = claims or {}
    checks = []
    for point in envelope.points:
        claim = claims.get(point.name, PointClaim())
        verdict = verify_gains(
            point.plant, gains[point.name], claim.certificate or None, claim.gamma_e, claim.gamma_z, seed=seed
        )
        checks.append(PointCheck(point.name, verdict))
    holds, detail = check_common(envelope, gains, common)
    mats = [_point_matrices(p.plant, gains[p.name]) for p in envelope.points]
    peak, growth = switching_growth(mats, samples=samples, seed=seed)
    bounded = bool(np.isfinite(peak) and growth < 1.0)
    stable = bool(all(c.verdict.stable for c in checks) and holds and bounded)
    return EnvelopeVerdict(
        stable=stable,
        points=checks,
        common_certificate=holds,
        gamma_common=float(common.gamma) if common is not None else None,  # claimed; common_certificate: verified
        common_detail=detail,
        switching_sim_max=peak,
        switching_sim_growth=growth,
        switching_bounded=bounded,
        switching_samples=samples,
    )
