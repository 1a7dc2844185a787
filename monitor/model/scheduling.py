"""Scheduling an envelope's points on the measured values: which point, whether inside, and the trim between them.

Pure functions of the envelope's lookup table (:class:`Schedule`) and the estimator's state vector; the live loop
(``monitor.service.vehicles``) calls them once per sample and owns the state they decide about.

**Which point: the nearest, with hysteresis.** Distances are taken in the schedule's variables each divided by
the points' spread of it (as :meth:`Envelope.nearest`: airspeed in m/s and bank in deg weigh alike), Euclidean.
From the current point ``c`` the scheduler moves to the nearest point ``j`` only when ``j`` is nearer than ``c`` by
``HYSTERESIS`` (10 %) of the distance between ``c`` and ``j``: ``d(x, c) - d(x, j) > 0.1 d(c, j)``. On one
variable that is 5 % of the spacing past the midpoint of the two points, and the way back 5 % short of it: a
dead band 10 % of the spacing wide about each midpoint, so a value wandering about a midpoint (turbulence on
the airspeed) does not chatter between the points. Why a band and not a dwell time: the envelope's certificate
covers switching at any rate (docs/explanation/envelope.md), so the band is not needed for stability; it keeps
the model (gains and matrices) from chattering, and a band in the measured variable adds no delay to a real
change of flight condition.

**Inside or outside the identified range.** Per variable, with the points' distinct values ``v_1 < ... < v_N``:
inside when ``v_1 - (v_2 - v_1)/2 <= x <= v_N + (v_N - v_{N-1})/2``, i.e. no further below the lowest point or
above the highest than half the spacing to its neighbour (as far as the outermost points would serve if the
envelope went on with the same spacing). With two variables, also within ``HULL_MARGIN`` (a tenth of each
variable's spread) of the points' convex hull: a corner of the box that no point covers (a steep turn at approach
speed, when the turns were identified at cruise) is a combination never identified, and flagged. A variable with
a single value across the points (every point at the same bank) bounds nothing. Outside, the estimator still runs
on the nearest point (the estimate goes on) but the live loop pauses the alarm (``monitor.service.vehicles``).

**The trim, interpolated; the state re-based to it.** The estimator's state ``z = [x_hat; f_hat; u(k-1)]`` is in
deviations from a trim: the points' trims (``y0``, ``u0`` of their ``[signals]``, and their offsets ``w_p``
below) weighted by :func:`trim_weights` at the sample's schedule values, so that the trim follows the flight
instead of jumping at a switch. Each sample the state moves from the last trim's deviations to the new one's,
keeping the absolute quantities; between two points' trims: with ``T_p = pinv(C_p)`` (the state that the outputs'
trim gives),

    x_hat_j  = x_hat_i + T_i y0_i - T_j y0_j          (= x_hat_i + T (y0_i - y0_j) when the points share C)
    u(k-1)_j = u(k-1)_i + (u0_i - u0_j)               (and each command still in flight of a lagged plant)
    f_hat_j  = f_hat_i                                 (an additive actuator fault is the same at every point)

The state's operating point is known only through the outputs: ``T (y0_i - y0_j)`` is exact when ``C`` is
invertible, which it is for identified models (``C = I``: every state is measured), and the least-squares
estimate of the trim's move otherwise (an unmeasured state's trim is taken as unchanged). Written as
``z_j = z_i + w_i - w_j`` with one offset ``w_p`` per point, re-basing from ``i`` to ``j`` and back is the
identity, and an interpolated trim's offset is the same weighted sum of the ``w_p``. The reported channel's
low-pass state (``EstimatorState.f_reported``) is ``f_hat``'s and is kept.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.model.envelope import Envelope
from monitor.model.flight_condition import needed_signals, schedule_value

__all__ = [
    "HYSTERESIS",
    "Schedule",
    "schedule_of",
    "make_schedule",
    "distances",
    "choose_point",
    "outside_variables",
    "hull_gap",
    "state_offset",
    "rebase",
    "values_in_order",
    "trim_weights",
]

HYSTERESIS = 0.1  # switch when the new point is nearer by this fraction of the distance between the two points


@dataclass(frozen=True, eq=False)
class Schedule:
    """An envelope's lookup table: each point's place (``at``, ``(points, variables)``), each variable's scale
    (the points' spread of it, 1 where they all share a value) and the identified range per variable."""

    names: tuple[str, ...]  # the schedule's variables
    points: tuple[str, ...]  # the points' names, in the envelope's order
    at: np.ndarray
    scale: np.ndarray
    low: np.ndarray  # the lowest point's value of each variable, and how far below it is still inside
    high: np.ndarray
    below: np.ndarray
    above: np.ndarray
    triangulation: Any = None  # scipy's Delaunay of the scaled points (two variables, not on one line), for trims

    def inside_range(self, i: int) -> tuple[float, float]:
        """The points' values of variable ``i`` (lowest, highest): the identified envelope as a message names it."""
        return float(self.low[i]), float(self.high[i])


def schedule_of(envelope: Envelope) -> Schedule:
    """The envelope's lookup table."""
    return make_schedule(envelope.schedule, envelope.names, envelope.at_matrix)


def make_schedule(names: Sequence[str], points: Sequence[str], at: np.ndarray) -> Schedule:
    """A lookup table from the points' places ``at`` (``(points, variables)``, in ``names``' order)."""
    at = np.array(at, dtype=float).reshape(len(points), len(names))
    scale = np.ptp(at, axis=0)
    scale[scale == 0] = 1.0
    below, above = [], []
    for column, spread in zip(at.T, np.ptp(at, axis=0), strict=True):
        values = _levels(column, spread)
        if values.size < 2:  # one value across the points: this variable bounds nothing (module docstring)
            below.append(np.inf)
            above.append(np.inf)
        else:
            below.append(0.5 * (values[1] - values[0]))
            above.append(0.5 * (values[-1] - values[-2]))
    triangulation = None
    if _line_of(at / scale) is None:
        from scipy.spatial import Delaunay

        triangulation = Delaunay(at / scale)
    return Schedule(
        names=tuple(names),
        points=tuple(points),
        at=at,
        scale=scale,
        low=at.min(axis=0),
        high=at.max(axis=0),
        below=np.array(below),
        above=np.array(above),
        triangulation=triangulation,
    )


LEVEL_TOLERANCE = 0.1  # of a variable's spread: points closer than this along it are at one level of it


def _levels(column: np.ndarray, spread: float) -> np.ndarray:
    """The distinct levels of one schedule variable across the points, values closer than ``LEVEL_TOLERANCE`` of
    its spread counted as one (the first of them; the outermost is kept at each end). Why: the turn legs of an
    identification flight are flown at the cruise speed and identified a few tenths of a knot apart; taken as
    levels of their own, they would leave the envelope half a tenth of a knot of room above cruise."""
    values = np.unique(column)
    if values.size < 2:
        return values
    kept = [values[0]]
    for v in values[1:]:
        if v - kept[-1] > LEVEL_TOLERANCE * spread:
            kept.append(v)
    kept[-1] = values[-1]
    return np.array(kept)


def distances(schedule: Schedule, x: Sequence[float]) -> np.ndarray:
    """The scaled Euclidean distance from ``x`` (the schedule's values, in its order) to every point."""
    diff = (schedule.at - np.asarray(x, dtype=float)) / schedule.scale
    out: np.ndarray = np.sqrt(np.sum(diff * diff, axis=1))
    return out


def choose_point(schedule: Schedule, x: Sequence[float], current: int | None, margin: float = HYSTERESIS) -> int:
    """The point to use for values ``x``: the nearest, but from ``current`` only when the nearest is nearer by
    ``margin`` times the distance between the two points (module docstring); ``current`` None: the nearest."""
    d = distances(schedule, x)
    nearest = int(np.argmin(d))
    if current is None or nearest == current:
        return nearest
    spacing = float(np.sqrt(np.sum(((schedule.at[current] - schedule.at[nearest]) / schedule.scale) ** 2)))
    return nearest if d[current] - d[nearest] > margin * spacing else current


HULL_MARGIN = 0.1  # of each variable's spread: how far beyond the points' hull (two variables) is still inside


def outside_variables(schedule: Schedule, x: Sequence[float]) -> list[int]:
    """The schedule variables whose value lies outside the identified range (module docstring); empty: inside.
    A non-finite value is outside. On two variables, a sample beyond the points' convex hull by more than
    ``HULL_MARGIN`` (scaled) is outside on both, though each value alone is within its range: a combination never
    identified (a 45 deg turn at approach speed, when the turns were identified at cruise) is extrapolated, and
    on c172p that read 1.5 deg of fault where none was."""
    out = []
    for i, value in enumerate(x):
        v = float(value)
        if not np.isfinite(v) or v < schedule.low[i] - schedule.below[i] or v > schedule.high[i] + schedule.above[i]:
            out.append(i)
    if not out and schedule.triangulation is not None and hull_gap(schedule, x) > HULL_MARGIN:
        out = list(range(len(x)))
    return out


def hull_gap(schedule: Schedule, x: Sequence[float]) -> float:
    """The scaled distance from ``x``, clipped to the points' range of each variable, to the points' convex hull:
    0 inside it, or without a triangulation. Why clipped: beyond the outermost points the per-variable margin
    (half a spacing) rules, as on one variable; the hull judges the combinations within the ranges."""
    tri = schedule.triangulation
    if tri is None:
        return 0.0
    p = np.clip(np.asarray(x, dtype=float), schedule.low, schedule.high) / schedule.scale
    if int(tri.find_simplex(p)) >= 0:
        return 0.0
    return _closest_on_hull(tri, schedule.at / schedule.scale, p)[0]


def _closest_on_hull(tri: Any, scaled: np.ndarray, p: np.ndarray) -> tuple[float, int, int, float]:
    """``(distance, a, b, t)``: the hull's closest point to ``p``, ``(1 - t)`` of point ``a`` and ``t`` of ``b``."""
    best = (np.inf, 0, 0, 0.0)
    for a, b in tri.convex_hull:
        edge = scaled[b] - scaled[a]
        t = float(np.clip((p - scaled[a]) @ edge / (edge @ edge), 0.0, 1.0))
        gap = float(np.linalg.norm(p - scaled[a] - t * edge))
        if gap < best[0]:
            best = (gap, int(a), int(b), t)
    return best


def state_offset(
    C: np.ndarray, y0: Sequence[float], u0: Sequence[float], n: int, q: int, lag_slots: int = 0
) -> np.ndarray:
    """A point's offset ``w_p`` in the estimator's state ``[x_hat; f_hat; u(k-1)]`` (module docstring).

    ``C``: the physical plant's output matrix (without the commands in flight); ``n``: the estimator's state size,
    the physical states and ``lag_slots`` commands in flight after them; ``q``: the faults."""
    u = np.asarray(u0, dtype=float)
    x = np.linalg.pinv(np.asarray(C, dtype=float)) @ np.asarray(y0, dtype=float)
    w = np.zeros(n + q + u.size)
    w[: x.size] = x
    for s in range(lag_slots):
        w[x.size + s * u.size : x.size + (s + 1) * u.size] = u
    w[n + q :] = u
    return w


def rebase(z: np.ndarray, offset_from: np.ndarray, offset_to: np.ndarray) -> np.ndarray:
    """The state ``z`` of a point with offset ``offset_from`` in the deviations of the point with ``offset_to``."""
    out: np.ndarray = np.asarray(z, dtype=float) + (offset_from - offset_to)
    return out


def values_in_order(schedule: Schedule, values: Mapping[str, float]) -> list[float] | None:
    """The schedule's values from a sample's ``{name: value}`` in the schedule's order (a flight-condition
    quantity such as ``bank_load_factor`` computed from its signals); None when one is absent."""
    out = []
    for name in schedule.names:
        if not all(s in values for s in needed_signals([name])):
            return None
        out.append(schedule_value(name, values))
    return out


def trim_weights(schedule: Schedule, x: Sequence[float]) -> np.ndarray:
    """Weights over the points (non-negative, summing to 1) that interpolate the points' trims at ``x``.

    Linear: on one variable (or points that all lie on a line in the scaled schedule) between the two points
    that bracket ``x`` along it; on two, barycentric in the Delaunay triangle of the scaled points that contains
    ``x``. Outside the points' span the trim of the span's closest point (an end point on one variable; on two,
    the closest point of the hull, between the ends of its edge): no extrapolation of a trim, and no jump at the
    hull either. Why that matters: the turn legs of an identification flight are flown at cruise speed, so the
    hull's side there is nearly along the bank's load factor, and an aircraft a knot fast in a turn is outside it;
    taking the nearest point there made the trim jump by half the difference of two points (on c172p, 3 deg/s of
    pitch rate in a roll-out from 45 deg), which the estimator read as a fault. A point's own place gives that
    point alone, so a single trim is what it was. Non-finite ``x``: the nearest
    point cannot be told either, and the first point's weight is 1 (the caller keeps its point then)."""
    xs = np.asarray(x, dtype=float)
    n = len(schedule.points)
    w = np.zeros(n)
    if not np.all(np.isfinite(xs)):
        w[0] = 1.0
        return w
    scaled = schedule.at / schedule.scale
    p = xs / schedule.scale
    line = _line_of(scaled)
    if line is not None:
        origin, direction = line
        s = (scaled - origin) @ direction
        t = float((p - origin) @ direction)
        order = np.argsort(s)
        if t <= s[order[0]]:
            w[order[0]] = 1.0
        elif t >= s[order[-1]]:
            w[order[-1]] = 1.0
        else:
            hi = int(np.searchsorted(s[order], t))
            a, b = order[hi - 1], order[hi]
            lam = (t - s[a]) / (s[b] - s[a]) if s[b] > s[a] else 0.0
            w[a], w[b] = 1.0 - lam, lam
        return w
    tri = schedule.triangulation
    simplex = int(tri.find_simplex(p))
    if simplex < 0:  # beyond the hull: the hull's closest point, between the two ends of its edge
        _gap, a, b, t = _closest_on_hull(tri, scaled, p)
        w[a] += 1.0 - t
        w[b] += t
        return w
    vertices = tri.simplices[simplex]
    T = tri.transform[simplex]
    bary = T[:2] @ (p - T[2])
    lam = np.clip(np.append(bary, 1.0 - bary.sum()), 0.0, 1.0)
    w[vertices] = lam / lam.sum()
    return w


def _line_of(scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(origin, unit direction)`` when the scaled points lie on one line (one variable, or collinear), else None."""
    origin = scaled.mean(axis=0)
    centred = scaled - origin
    _u, sv, vt = np.linalg.svd(centred, full_matrices=False)
    if scaled.shape[1] == 1 or len(sv) < 2 or sv[1] <= 1e-9 * max(sv[0], 1e-300):
        return origin, vt[0]
    return None
