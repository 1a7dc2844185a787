"""The threshold calibrated from flights (``monitor.checks.calibration``): on series whose tails the Gaussian
prediction gets wrong, the calibrated threshold holds the budget on a long independent series where the prediction
does not, and it is not absurdly high."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from monitor.checks.calibration import calibrate_threshold, crossing_rates
from monitor.checks.detectability import gaussian_threshold

H = 0.05
RHO = 0.95
BUDGET = 60.0  # per hour: low enough to need extrapolation from half an hour, high enough to verify on 20 hours


def ar1(n: int, rng: np.random.Generator, std: float = 1.0) -> np.ndarray:
    """A stationary AR(1) of lag-one correlation RHO and standard deviation ``std``."""
    e = rng.normal(0.0, std * math.sqrt(1 - RHO**2), n)
    return scipy.signal.lfilter([1.0], [1.0, -RHO], e)


def heavy(n: int, rng: np.random.Generator) -> np.ndarray:
    """AR(1) times a slowly varying log-normal gain: heavier tails than its own std says (gusty air)."""
    gain = np.exp(0.35 * scipy.signal.lfilter([1.0], [1.0, -0.9995], rng.normal(0, math.sqrt(1 - 0.9995**2), n)))
    x = ar1(n, rng) * gain
    return x / x.std()


def rate_at(level: float, series: np.ndarray) -> float:
    return float(crossing_rates([series], np.array([level]), H)[1][0])


def test_the_crossing_rates_count_both_signs_per_hour() -> None:
    f = np.array([0.0, 1.0, 0.0, -1.0, 0.0, 1.0])  # +1 crossed upwards twice, -1 downwards once, in 6 samples
    counts, rates, hours = crossing_rates([f], np.array([0.5]), H)
    assert counts[0] == 3 and hours == pytest.approx(6 * H / 3600) and rates[0] == pytest.approx(3 / hours)


@pytest.mark.parametrize("make, underestimate", [(ar1, 0.93), (heavy, 1.0)])
def test_the_calibrated_threshold_holds_the_budget_where_the_prediction_does_not(make, underestimate) -> None:
    """The prediction: Rice on a Gaussian with the series' std (times ``underestimate``: the model's std a few per
    cent low, as in flight) and its correlation. Fit on half an hour, judge on twenty independent hours."""
    rng = np.random.default_rng(5)
    fit_on = [make(int(0.5 * 3600 / H), rng)]
    judge = make(int(20 * 3600 / H), np.random.default_rng(6))
    predicted = gaussian_threshold(underestimate * float(np.std(fit_on[0])), RHO, H, BUDGET)
    cal = calibrate_threshold(fit_on, H, BUDGET, predicted)
    assert cal is not None and cal.kept != "prediction"
    at_prediction, at_calibrated = rate_at(predicted, judge), rate_at(cal.threshold, judge)
    print(
        f"{make.__name__}: prediction {predicted:.3f} -> {at_prediction:.0f}/h, calibrated {cal.threshold:.3f} "
        f"({cal.kept}) -> {at_calibrated:.0f}/h, budget {BUDGET:g}/h"
    )
    assert at_prediction > 1.5 * BUDGET  # the thin tail's threshold breaks the budget
    assert at_calibrated <= 1.3 * BUDGET  # the calibrated one holds it (to the judging series' own spread)
    assert at_calibrated >= BUDGET / 10  # and is not absurdly conservative
    assert cal.threshold < 1.5 * predicted


def test_too_few_crossings_to_fit_is_none() -> None:
    assert calibrate_threshold([np.zeros(100)], H, 1.0, 0.5) is None
    assert calibrate_threshold([np.array([0.0, 1.0, 0.0])], H, 1.0, 0.5) is None
