"""The observed-delay tracker on synthetic arrivals with known lateness."""

from __future__ import annotations

import numpy as np

from monitor.service.delay import DelayTracker


def test_observed_delay_is_never_negative_and_recovers_lateness():
    rng = np.random.default_rng(0)
    speedup = 10.0
    tracker = DelayTracker()
    errors = []
    for k in range(400):
        late = float(rng.uniform(0.0, 0.3))  # vehicle seconds
        late = 0.0 if k % 25 == 0 else late  # best-case arrivals now and then
        wall = 1000.0 + (k + late) / speedup
        tau = tracker.update(float(k), wall)
        if tau is None:
            continue
        assert tau >= 0.0
        if k > 100:
            errors.append(tau - late)
    assert np.percentile(np.abs(errors), 90) < 0.05


def test_nothing_before_enough_samples():
    tracker = DelayTracker(min_samples=3)
    assert tracker.update(0.0, 10.0) is None
    assert tracker.update(1.0, 10.1) is None
    assert tracker.update(2.0, 10.2) is not None
