"""How the uncertain delay moves the input matrices: the curve ``tau -> B0(tau)`` and a polytope around it.

Both plant forms have ``B0(tau) + B1(tau) = B0 + B1`` for every ``tau``, so the delay is one matrix
``B0(tau)`` and the closed loop is affine in it. That is what makes a polytopic certificate sound:
if ``B0(tau)`` lies in the convex hull of a few vertices for every ``tau`` in the interval, one common
Lyapunov matrix that works at every vertex works for any sequence ``tau(k)``.

* continuous form: ``B0(tau)`` is exact (``monitor.model.discretize``).
* discrete form: ``B0(tau) = B0 + F(tau) E`` with the paper's own ``F(tau)`` computed from the
  reconstructed ``A_c = logm(A)/h`` and ``E`` from the file (or the reconstructed ``B_c``).
* a delay past one sample (``plant.lags``, ``monitor.model.long_delay``): the uncertain "point" is the stack
  ``[G(a_first); ...; G(a_last)]`` of one curve value per whole-sample part, and ``A`` varies too; the
  functions here take and return such points, and :func:`realization` turns one into ``(A, B0, B1)``. For an
  ordinary plant the point is ``B0(tau)`` itself, so every caller stays the same.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from functools import lru_cache

import numpy as np

from monitor.model.discretize import F_of_tau, b0_b1, delta_exact, delta_lemma1, integral_expm, reconstruct_continuous
from monitor.model.long_delay import curve_of, lag_intervals, lag_point, lag_realization
from monitor.model.plant import ContinuousModel, Plant

__all__ = [
    "b0_of_tau",
    "tau_grid",
    "b0_polytope",
    "curve_model",
    "input_sum",
    "delta_summary",
    "lag_curve",
    "realization",
    "point_size",
    "nominal_point",
]


def input_sum(plant: Plant) -> np.ndarray:
    """``B0(tau) + B1(tau)``: the same for every delay."""
    total: np.ndarray = plant.B0 + plant.B1
    return total


@lru_cache(maxsize=32)
def _reconstruction(plant: Plant) -> ContinuousModel:
    return reconstruct_continuous(plant.A, input_sum(plant), plant.Df, plant.Dd, plant.h)


def curve_model(plant: Plant) -> ContinuousModel:
    """The continuous model whose exponentials define ``F(tau)``: the plant's own, or the reconstruction."""
    return plant.continuous if plant.continuous is not None else _reconstruction(plant)


def _E(plant: Plant) -> np.ndarray:
    return plant.E if plant.E is not None else curve_model(plant).B_c


@lru_cache(maxsize=32)
def lag_curve(base: Plant) -> Callable[[float], np.ndarray]:
    """``a -> G(a)`` for ``a`` in ``[0, h]`` (``monitor.model.long_delay.curve_of``) of the exact or
    reconstructed model."""
    model = curve_model(base)
    return curve_of(model.A_c, model.B_c, base.h)


def point_size(plant: Plant) -> int:
    """Entries of one uncertain point (a vertex of the certificate's polytope, raveled)."""
    if plant.lags is None:
        return plant.B0.size
    return (plant.lags.last - plant.lags.first + 1) * plant.lags.base.B0.size


def nominal_point(plant: Plant) -> np.ndarray:
    """The uncertain point at the nominal delay: ``plant.B0`` for an ordinary plant; what gives the lagged
    plant's own ``A, B0, B1`` past one sample (where ``plant.B0`` is not a point)."""
    return plant.B0 if plant.lags is None else b0_of_tau(plant, plant.tau_bar)


def realization(plant: Plant, point: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B0, B1)`` that act at one uncertain point: ``(A, B0(tau), B0 + B1 - B0(tau))`` for an ordinary plant."""
    if plant.lags is None:
        return plant.A, point, input_sum(plant) - point
    lags = plant.lags
    if point.shape != (point_size(plant) // plant.m, plant.m):
        raise ValueError(
            f"an uncertain point of this lagged plant is {point_size(plant) // plant.m} x {plant.m}, "
            f"got {point.shape[0]} x {point.shape[1]}"
        )
    return lag_realization(point, lags.base.A, _whole_interval(lags.base), lags.first, lags.last)


@lru_cache(maxsize=32)
def _whole_interval(base: Plant) -> np.ndarray:
    return lag_curve(base)(0.0)


def b0_of_tau(plant: Plant, tau: float) -> np.ndarray:
    """``B0(tau)`` for a delay in ``[0, h)``; ``B1(tau)`` is ``input_sum(plant) - B0(tau)``. Past one sample
    (``plant.lags``): the point of a constant delay ``tau``, ``[G(a_first); ...]``.

    Cached per (plant, tau): the design searches ask for the same few delays at every candidate, and each
    costs two matrix exponentials. Plants are immutable and hash by identity; the copy keeps callers from
    changing the cached matrix.
    """
    return _b0_of_tau(plant, float(tau)).copy()


@lru_cache(maxsize=1024)
def _b0_of_tau(plant: Plant, tau: float) -> np.ndarray:
    if plant.lags is not None:
        return lag_point(lag_curve(plant.lags.base), plant.h, plant.tau_min, plant.tau_max, tau)
    if plant.continuous is not None:
        return b0_b1(plant.continuous, plant.h, tau)[0]
    b0: np.ndarray = plant.B0 + F_of_tau(curve_model(plant), plant.h, tau, plant.tau_bar) @ _E(plant)
    return b0


def tau_grid(plant: Plant, points: int = 201) -> np.ndarray:
    """A dense grid over ``[tau_min, tau_max]`` (both ends included)."""
    if plant.tau_max == plant.tau_min:
        return np.array([plant.tau_min])
    return np.linspace(plant.tau_min, plant.tau_max, points)


def _second_derivative_bound(plant: Plant, lo: float, hi: float, A_c: np.ndarray, B: np.ndarray) -> float:
    """An upper bound of ``|d^2 B0 / d tau^2|`` over ``[lo, hi]`` (Frobenius norm).

    ``dB0/dtau = -e^{A_c (h - tau)} B`` and ``d^2B0/dtau^2 = A_c e^{A_c (h - tau)} B`` with ``B = B_c`` (continuous)
    or ``E`` (discrete); bounded on a fine grid with a 10 % margin for the gaps between grid points.
    """
    values = [np.linalg.norm(A_c @ integral_expm(A_c, plant.h - t)[0] @ B) for t in np.linspace(lo, hi, 101)]
    return float(1.1 * max(values))


def b0_polytope(plant: Plant, segments: int = 8) -> list[np.ndarray]:
    """Vertices of a polytope that provably contains ``B0(tau)`` for every ``tau`` in the interval.

    The curve is split into ``segments`` chords; between two grid points it stays within
    ``r = dtau^2 / 8 * max|B0''|`` of its chord (the interpolation error bound), so the hull of the grid
    points, each blown up into a cross-polytope that contains a ball of radius ``r``, contains it.
    Redundant points are pruned with a convex hull where the dimension allows.

    Past one sample: one such polytope per whole-sample part, over the arrival window ``[lo_j, hi_j]`` of
    ``G(a_j)``, and the vertices of their product (every part may sit anywhere in its window at once).
    """
    if plant.lags is None:
        model = curve_model(plant)
        B = model.B_c if plant.continuous is not None else _E(plant)
        return _curve_polytope(
            plant, lambda t: b0_of_tau(plant, t), plant.tau_min, plant.tau_max, model.A_c, B, segments
        )
    base = plant.lags.base
    model, curve = curve_model(base), lag_curve(base)
    parts = [
        _curve_polytope(base, curve, lo, hi, model.A_c, model.B_c, segments)
        for lo, hi in lag_intervals(plant.h, plant.tau_min, plant.tau_max)
    ]
    return [np.vstack(choice) for choice in itertools.product(*parts)]


def _curve_polytope(
    plant: Plant,
    curve: Callable[[float], np.ndarray],
    lo: float,
    hi: float,
    A_c: np.ndarray,
    B: np.ndarray,
    segments: int,
) -> list[np.ndarray]:
    """The vertices for ``curve`` (``B0`` of a delay) over ``[lo, hi]``: chords blown up by their error bound."""
    taus = np.linspace(lo, hi, segments + 1)
    points = [curve(float(t)).ravel() for t in taus]
    shape = plant.B0.shape
    dim = points[0].size
    if hi == lo:
        return [points[0].reshape(shape)]
    dtau = (hi - lo) / segments
    radius = dtau**2 / 8.0 * _second_derivative_bound(plant, lo, hi, A_c, B) * np.sqrt(dim) * 1.001
    cloud = np.array([pt + s * radius * e for pt in points for e in np.eye(dim) for s in (1.0, -1.0)])
    chosen = min((_prune(cloud), _oriented_box(cloud), _oriented_prism(cloud)), key=len)
    return [v.reshape(shape) for v in chosen]


def _oriented_box(cloud: np.ndarray) -> np.ndarray:
    """The corners of a box aligned with the cloud's principal axes that contains every point.

    Why: the curve is short and nearly straight, so a thin box (2^dim corners) holds it with far fewer
    vertices than its hull, and each vertex costs two LMIs in the design.
    """
    centre = cloud.mean(axis=0)
    _, _, axes = np.linalg.svd(cloud - centre, full_matrices=True)
    coords = (cloud - centre) @ axes.T
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    dim = cloud.shape[1]
    if dim > 10:
        return cloud
    corners = np.array(np.meshgrid(*[(a, b) for a, b in zip(lo, hi, strict=True)], indexing="ij")).reshape(dim, -1).T
    box: np.ndarray = centre + corners @ axes
    return box


def _oriented_prism(cloud: np.ndarray) -> np.ndarray:
    """A prism along the cloud's main axis over a simplex in the thin directions: ``2 dim`` vertices.

    Why: the box has ``2^dim`` corners (16 for a 4-state aircraft), and each vertex costs LMIs in every
    design. The curve's length lies along one axis; across it the cloud is only as thick as its curvature
    and the chord error, so a simplex there (``dim`` vertices, stretched by ``dim - 1`` in those thin
    directions) costs little conservatism and halves the count at dim = 4. Contains the principal box.
    """
    centre = cloud.mean(axis=0)
    _, _, axes = np.linalg.svd(cloud - centre, full_matrices=True)
    coords = (cloud - centre) @ axes.T
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    dim = cloud.shape[1]
    if dim < 3:
        return cloud
    width = hi[1:] - lo[1:]
    # the thin simplex {y >= lo, sum_j (y_j - lo_j) / w_j <= dim - 1} holds the thin box
    thin = [lo[1:]] + [lo[1:] + (dim - 1) * w * e for w, e in zip(width, np.eye(dim - 1), strict=True)]
    corners = np.array([np.concatenate([[end], t]) for end in (lo[0], hi[0]) for t in thin])
    return np.unique(centre + corners @ axes, axis=0)


def _prune(cloud: np.ndarray) -> np.ndarray:
    """Keep the convex-hull vertices (Qhull) when the dimension is small; the hull is unchanged."""
    if cloud.shape[1] > 6 or cloud.shape[1] < 2:
        return cloud
    try:
        from scipy.spatial import ConvexHull

        hull: np.ndarray = cloud[ConvexHull(cloud).vertices]
        return hull
    except Exception:  # degenerate (flat) clouds: keep every point, still a valid cover
        return cloud


def delta_summary(plant: Plant) -> dict[str, float | None]:
    """The delay figures a user wants next to a design: tau_bar, Lemma 1's delta as printed, the plant
    file's delta, and the exact ``max |F(tau)|`` (from the reconstructed A_c for a discrete plant)."""
    tau_bar = plant.tau_bar
    return {
        "tau_bar": tau_bar,
        "delta_lemma1": delta_lemma1(plant.A, plant.h, plant.tau_min, tau_bar),
        "delta_file": plant.delta,
        "delta_exact": delta_exact(curve_model(plant), plant.h, plant.tau_min, plant.tau_max, tau_bar),
    }
