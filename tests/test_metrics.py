"""Each metric on hand-made signals whose answer is obvious by inspection."""

from __future__ import annotations

import math

import numpy as np
import pytest

from monitor.checks import metrics


def _bias_run(n: int = 60, onset: int = 20, size: float = 2.0, lag: int = 5) -> tuple[np.ndarray, ...]:
    """f steps to ``size`` at ``onset``; f_hat follows exactly ``lag`` steps later."""
    k = np.arange(n)
    f = np.where(k >= onset, size, 0.0)
    f_hat = np.where(k >= onset + lag, size, 0.0)
    return k, f_hat, f


def test_settling_counts_steps_after_onset() -> None:
    k, f_hat, f = _bias_run(lag=5)
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0) == 5


def test_settling_requires_staying_within_tolerance() -> None:
    k, f_hat, f = _bias_run(lag=5)
    f_hat[40] = 1.8  # 10 % off, once: the run only settles after it
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0) == 21
    f_hat[40] = 1.95  # 2.5 % off: inside the 5 % band
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0) == 5


def test_settling_none_when_never_settled_or_no_fault() -> None:
    k, f_hat, f = _bias_run(lag=5)
    f_hat[-1] = 0.0
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0) is None
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=0.0) is None
    assert metrics.settling_steps(k, f_hat, f, onset=100, size=2.0) is None
    f_hat[-1] = math.nan
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0) is None


def test_settling_uses_k_not_positions_and_honours_stop() -> None:
    k, f_hat, f = _bias_run(lag=5)
    keep = k != 24  # sample 24 lost: still 5 steps, not 4 positions
    assert metrics.settling_steps(k[keep], f_hat[keep], f[keep], onset=20, size=2.0) == 5
    f_hat[50:] = 0.0  # intermittent fault scored on [20, 50) only
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0, stop=50) == 5
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0, stop=None) is None


def test_settling_zero_when_right_from_onset() -> None:
    k, f_hat, f = _bias_run(lag=0)
    assert metrics.settling_steps(k, f_hat, f, onset=20, size=2.0) == 0


def test_rms_and_rms_error_window() -> None:
    assert metrics.rms([3.0, -4.0]) == pytest.approx(math.sqrt(12.5))
    assert metrics.rms([]) is None
    k, f_hat, f = _bias_run(lag=5)  # error 2 on k = 20..24, else 0
    assert metrics.rms_error(k, f_hat, f) == pytest.approx(math.sqrt(5 * 4 / 60))
    assert metrics.rms_error(k, f_hat, f, start=20, stop=30) == pytest.approx(math.sqrt(5 * 4 / 10))
    assert metrics.rms_error(k, f_hat, f, start=25) == 0.0
    assert metrics.rms_error(k, f_hat, f, start=100) is None


def test_detection_delay_and_first_alarm() -> None:
    k = np.arange(40)
    alarm = (k >= 23) | (k == 5)
    assert metrics.first_alarm(k, alarm) == 5
    assert metrics.first_alarm(k, alarm, start=20) == 23
    assert metrics.detection_delay(k, alarm, onset=20) == 3
    assert metrics.detection_delay(k, np.zeros(40, bool), onset=20) is None


def test_false_alarms_count_raises_before_onset() -> None:
    k = np.arange(40)
    alarm = np.zeros(40, bool)
    alarm[[3, 4, 5, 10, 19, 25]] = True  # raises at 3, 10 and 19 before onset 20; 25 is after
    assert metrics.false_alarms(k, alarm, onset=20) == 3
    assert metrics.false_alarms(k, alarm, onset=None) == 4
    assert metrics.false_alarms(k, alarm, onset=0) == 0
    assert metrics.false_alarms([], [], onset=20) == 0


def test_peak_abs() -> None:
    assert metrics.peak_abs([0.5, -3.0, 2.0, math.nan]) == 3.0
    assert metrics.peak_abs([]) is None


def test_percentiles() -> None:
    stats = metrics.percentiles(list(range(1, 101)) + [math.nan])
    assert stats is not None
    assert stats["n"] == 100 and stats["max"] == 100.0 and stats["mean"] == pytest.approx(50.5)
    assert stats["p50"] == pytest.approx(50.5)
    assert stats["p99"] == pytest.approx(99.01)
    assert metrics.percentiles([]) is None
