"""A false-alarm threshold calibrated from flights: where the crossings of ``|f_hat|`` the flights show put the
budget, when the Gaussian prediction's tail is too thin.

Why: the threshold ``detectability`` sets is Rice's formula on a Gaussian ``f_hat`` whose variance and correlation
come from the linear model. In flight the estimate is not quite that: its std comes out a few per cent above the
model's (a 7 % larger sigma at 4.3 sigma crosses three times as often), and its tails are heavier (the plant is
not linear, the gusts are not the model's first-order process). Flights measure the crossing rate well only where
there are many crossings, far below a threshold meant for one alarm per hour; so the calibration fits the
measured rates and extrapolates the fit, two ways:

* **Gaussian-shaped**: ``log nu(c) = a - c^2 / (2 s^2)`` (Rice's shape, its own ``a`` and ``s``);
* **exponential**: ``log nu(c) = a - c / l`` (a heavier tail: it falls more slowly, so it asks for a higher c).

Each is a least-squares line through ``(c^2 or c, log nu)`` over the levels crossed at least ``MIN_CROSSINGS``
times in the upper half of the measured range, weighted by the counts (a count's log has variance ~1/count). The
calibrated threshold is the largest of the Gaussian prediction and the two fits' levels for the budget: the fit
that a heavier tail would need is the one kept. How conservative it is: the budget is what the kept fit gives
there, and the other fit's rate at the same level is reported next to it (the truth lies between when the tail is
between the two shapes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["MIN_CROSSINGS", "CrossingFit", "Calibration", "crossing_rates", "calibrate_threshold"]

MIN_CROSSINGS = 8  # a level crossed fewer times than this is too noisy to fit (the count's own spread is ~35 %)
LEVELS = 40  # levels from 0 to the largest |f_hat| seen


@dataclass(frozen=True)
class CrossingFit:
    shape: str  # "gaussian" or "exponential"
    a: float  # log of the rate per hour at c = 0 (both signs)
    scale: float  # s (gaussian) or l (exponential), in f_hat's unit
    threshold: float  # where the fit gives the budget

    def per_hour(self, level: float) -> float:
        x = level**2 / (2 * self.scale**2) if self.shape == "gaussian" else level / self.scale
        return math.exp(self.a - x)


@dataclass(frozen=True)
class Calibration:
    threshold: float  # the calibrated threshold: the largest of the Gaussian one and the fits'
    gaussian_threshold: float  # the prediction's (Rice on the linear model)
    per_hour: float  # the budget
    kept: str  # which gave the threshold: "prediction", "gaussian" or "exponential"
    fits: tuple[CrossingFit, ...]
    levels: tuple[float, ...]  # the levels fitted, and their measured rates per hour (both signs)
    rates: tuple[float, ...]
    hours: float
    prediction_per_hour_by_flights: float  # what the kept fit says the Gaussian threshold would give
    other_fit_per_hour: float | None  # the other fit's rate at the calibrated threshold (the less conservative one)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def crossing_rates(series: Sequence[np.ndarray], levels: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``(counts, rates per hour, hours)``: upcrossings of ``+c`` and downcrossings of ``-c`` per level, pooled."""
    counts = np.zeros(len(levels))
    samples = 0
    for f in series:
        f = np.asarray(f, dtype=float)
        samples += len(f)
        for i, c in enumerate(levels):
            counts[i] += np.sum((f[:-1] < c) & (f[1:] >= c)) + np.sum((f[:-1] > -c) & (f[1:] <= -c))
    hours = samples * h / 3600.0
    return counts, counts / hours, hours


def _fit(shape: str, levels: np.ndarray, counts: np.ndarray, hours: float, per_hour: float) -> CrossingFit | None:
    x = levels**2 if shape == "gaussian" else levels
    y = np.log(counts / hours)
    w = counts
    if len(x) < 3 or np.ptp(x) == 0:
        return None
    A = np.column_stack([np.ones_like(x), x]) * np.sqrt(w)[:, None]
    (a, slope), *_ = np.linalg.lstsq(A, y * np.sqrt(w), rcond=None)
    if not slope < 0:
        return None
    scale = math.sqrt(-1.0 / (2.0 * slope)) if shape == "gaussian" else -1.0 / slope
    excess = a - math.log(per_hour)  # log(nu(0) / budget): the budget is reached where x/scale-term equals it
    if excess <= 0:
        threshold = 0.0
    else:
        threshold = scale * math.sqrt(2.0 * excess) if shape == "gaussian" else scale * excess
    return CrossingFit(shape, float(a), float(scale), float(threshold))


def calibrate_threshold(
    series: Sequence[np.ndarray], h: float, per_hour: float, gaussian_threshold: float
) -> Calibration | None:
    """The calibrated threshold from fault-free ``series`` of f_hat (module docstring); None when the flights
    cross too few levels often enough to fit."""
    peak = max((float(np.max(np.abs(f))) for f in series if len(f)), default=0.0)
    if not peak > 0:
        return None
    levels = np.linspace(0.0, peak, LEVELS + 1)[1:]
    counts, rates, hours = crossing_rates(series, levels, h)
    usable = counts >= MIN_CROSSINGS
    if np.count_nonzero(usable) < 3:
        return None
    top = levels[usable].max()
    fitted = usable & (levels >= 0.5 * top)
    if np.count_nonzero(fitted) < 3:
        fitted = usable
    fits = tuple(
        fit
        for fit in (_fit(s, levels[fitted], counts[fitted], hours, per_hour) for s in ("gaussian", "exponential"))
        if fit is not None
    )
    candidates = [("prediction", gaussian_threshold)] + [(fit.shape, fit.threshold) for fit in fits]
    kept, threshold = max(candidates, key=lambda kv: kv[1])
    kept_fit = next((fit for fit in fits if fit.shape == kept), None)
    by_flights = max((fit.per_hour(gaussian_threshold) for fit in fits), default=math.nan)
    other = next((fit.per_hour(threshold) for fit in fits if fit.shape != kept), None) if kept_fit else None
    return Calibration(
        threshold=float(threshold),
        gaussian_threshold=float(gaussian_threshold),
        per_hour=float(per_hour),
        kept=kept,
        fits=fits,
        levels=tuple(float(c) for c in levels[fitted]),
        rates=tuple(float(r) for r in rates[fitted]),
        hours=float(hours),
        prediction_per_hour_by_flights=float(by_flights),
        other_fit_per_hour=None if other is None else float(other),
    )
