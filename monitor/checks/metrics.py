"""Scores of one vehicle's run: how fast and how well the fault was estimated and detected.

Pure functions on plain sequences (no I/O, no clocks) so that ``replay`` (from a recording), the demo
(from a live run) and the tests score a run the same way. Every signal comes with its sample indices
``k``: telemetry can be lost, so position in the array is not time, and results are in samples of
``k`` (steps), never array positions. ``onset`` is the first faulty sample. Empty inputs give ``None``
rather than a made-up number.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "settling_steps",
    "rms",
    "rms_error",
    "first_alarm",
    "detection_delay",
    "false_alarms",
    "peak_abs",
    "percentiles",
]

ArrayLike = Sequence[float] | np.ndarray


def _arr(values: ArrayLike, dtype: type = float) -> np.ndarray:
    return np.asarray(values, dtype=dtype).reshape(-1)


def settling_steps(
    k: ArrayLike, f_hat: ArrayLike, f: ArrayLike, onset: int, size: float, tol: float = 0.05, stop: int | None = None
) -> int | None:
    """Steps after ``onset`` from which ``|f_hat - f| <= tol * |size|`` holds on every later sample.

    The window is ``onset <= k < stop`` (``stop`` None: to the end), so an intermittent fault is scored
    on its faulty episode only. Returns ``k_settled - onset`` (0 when within tolerance from the onset
    on), or ``None`` when the error is still out of tolerance at the last sample of the window, when the
    window holds no sample, or when ``size`` is 0 (no fault: nothing to settle on).
    """
    if size == 0:
        return None
    kk, fh, ff = _arr(k, np.int64), _arr(f_hat), _arr(f)
    window = (kk >= onset) & (kk < stop if stop is not None else True)
    kk, err = kk[window], np.abs(fh[window] - ff[window])
    if kk.size == 0:
        return None
    outside = np.flatnonzero(~(err <= tol * abs(size)))  # NaN counts as outside
    if outside.size == 0:
        return int(kk[0] - onset)
    last_bad = outside[-1]
    if last_bad == kk.size - 1:
        return None
    return int(kk[last_bad + 1] - onset)


def rms(values: ArrayLike) -> float | None:
    """Root mean square, or None for no values."""
    v = _arr(values)
    return float(np.sqrt(np.mean(v * v))) if v.size else None


def rms_error(
    k: ArrayLike, estimate: ArrayLike, truth: ArrayLike, start: int | None = None, stop: int | None = None
) -> float | None:
    """RMS of ``truth - estimate`` (e.g. ``e_f = f - f_hat``) on samples ``start <= k < stop``."""
    kk = _arr(k, np.int64)
    window = np.ones(kk.size, bool)
    if start is not None:
        window &= kk >= start
    if stop is not None:
        window &= kk < stop
    return rms(_arr(truth)[window] - _arr(estimate)[window])


def first_alarm(k: ArrayLike, alarm: ArrayLike, start: int | None = None) -> int | None:
    """The first sample ``k >= start`` (any sample when ``start`` is None) with the alarm raised."""
    kk, aa = _arr(k, np.int64), _arr(alarm, bool)
    if start is not None:
        aa = aa & (kk >= start)
    hits = np.flatnonzero(aa)
    return int(kk[hits[0]]) if hits.size else None


def detection_delay(k: ArrayLike, alarm: ArrayLike, onset: int) -> int | None:
    """Steps from ``onset`` to the first alarm at or after it (0: raised on the onset sample), or None."""
    hit = first_alarm(k, alarm, start=onset)
    return None if hit is None else hit - onset


def false_alarms(k: ArrayLike, alarm: ArrayLike, onset: int | None) -> int:
    """How many times the alarm was raised before ``onset`` (each raise counts once, however long).

    A raise is a sample with the alarm on whose previous recorded sample had it off (or that is the
    first sample). With ``onset`` None (a fault-free run) every raise is false.
    """
    kk, aa = _arr(k, np.int64), _arr(alarm, bool)
    if onset is not None:
        aa = aa[kk < onset]
    raises = aa & ~np.concatenate(([False], aa[:-1]))
    return int(raises.sum())


def peak_abs(values: ArrayLike) -> float | None:
    """Largest magnitude (e.g. peak |alpha|), ignoring NaN; None for no values."""
    v = np.abs(_arr(values))
    v = v[~np.isnan(v)]
    return float(v.max()) if v.size else None


def percentiles(values: ArrayLike) -> dict[str, float] | None:
    """``{"n", "mean", "p50", "p99", "max"}`` of the finite values (delays, processing times), or None."""
    v = _arr(values)
    v = v[np.isfinite(v)]
    if not v.size:
        return None
    p50, p99 = np.percentile(v, [50, 99])
    return {"n": int(v.size), "mean": float(v.mean()), "p50": float(p50), "p99": float(p99), "max": float(v.max())}
