"""The delay the monitor can observe: how late each sample arrives compared with its best-case arrival.

The monitor cannot see the vehicle's clock or the actuator, only the sample instant ``t_k`` stamped by the
vehicle and its own receive time ``a_k``. If the path added no delay, ``a_k = a_0 + r t_k`` with ``r``
the wall-clock seconds per vehicle second (1/speedup for the simulator). So:

* ``r`` is fitted by least squares of ``a`` on ``t`` over every sample so far (O(1) running sums);
* the residual ``a_k - (alpha + r t_k)`` minus its lower envelope (the best case seen, which may leak
  upward slowly so that an early, badly fitted line is forgotten) is the lateness of sample k;
* divided by ``r`` it is in the vehicle's seconds, comparable with the plant's ``tau``.

What it sees: the vehicle->monitor part of the network delay plus OS scheduling jitter. It cannot see
the command's way back or the actuator's hold, so it is a lower bound of the loop's total delay.
"""

from __future__ import annotations

__all__ = ["DelayTracker"]


class DelayTracker:
    """Per-vehicle observed delay; ``update(t, wall)`` returns seconds of vehicle time, None until fitted."""

    __slots__ = ("_t0", "_a0", "_n", "_st", "_sa", "_stt", "_sta", "_floor", "leak", "min_samples")

    def __init__(self, min_samples: int = 3, leak: float = 1e-3) -> None:
        self.min_samples = min_samples
        self.leak = leak  # fraction of one sample interval the envelope may rise per sample
        self._t0: float | None = None
        self._a0 = 0.0
        self._n = 0
        self._st = self._sa = self._stt = self._sta = 0.0
        self._floor: float | None = None

    def update(self, t: float, wall: float) -> float | None:
        if self._t0 is None:
            self._t0, self._a0 = t, wall
        x, y = t - self._t0, wall - self._a0
        self._n += 1
        n = self._n
        self._st += x
        self._sa += y
        self._stt += x * x
        self._sta += x * y
        if n < self.min_samples:
            return None
        var = n * self._stt - self._st * self._st
        if var <= 0.0:
            return None
        r = (n * self._sta - self._st * self._sa) / var
        if r <= 0.0:
            return None
        residual = y - (self._sa - r * self._st) / n - r * x
        span = x / max(n - 1, 1)  # mean sample interval in vehicle seconds
        floor = self._floor
        # the envelope leaks upward, but never past the current residual: a delay is never negative
        floor = residual if floor is None else min(floor + self.leak * r * span, residual)
        self._floor = floor
        return (residual - floor) / r
