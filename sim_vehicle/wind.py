"""Wind disturbance ``d(k)``, held constant over each sample interval (so the paper's ``Dd d(k)`` is exact).

Wind SPEC (several joined by ``+`` add up)::

    paper                   the paper's oscillator: s(k+1) = [[0.9922, 0.1247], [-0.1247, 0.9922]] s(k),
                            s(0) = [0.01, 0], d(k) = 0.1 s1(k)   (the default)
    turbulence:SIGMA[:TAU]  seeded first-order Gauss-Markov gusts, standard deviation SIGMA (plant units),
                            correlation time TAU seconds (default 2): d(k+1) = a d(k) + sqrt(1 - a^2) SIGMA w(k),
                            a = exp(-h / TAU), d(0) ~ N(0, SIGMA^2)
    none                    no wind

Why Gauss-Markov: it is the discrete form of the Dryden spectrum's first-order shape, stationary from
k = 0, and each draw is keyed by ``(seed, k)`` so runs are reproducible.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from monitor.errors import UserError

__all__ = ["Wind", "parse_wind_spec", "PAPER_ROTATION"]

PAPER_ROTATION = np.array([[0.9922, 0.1247], [-0.1247, 0.9922]])
PAPER_S0 = np.array([0.01, 0.0])
PAPER_GAIN = 0.1


@dataclass(frozen=True)
class Wind:
    """A sum of wind terms; ``values()`` yields ``d(k)`` as a scalar gust on the plant's first wind input."""

    oscillator: bool = True
    sigma: float = 0.0
    tau: float = 2.0
    h: float = 1.0
    seed: int = 0

    def series(self, n: int) -> np.ndarray:
        """``d(0), ..., d(n-1)``: the first ``n`` values of ``values()``."""
        return np.fromiter(itertools.islice(self.values(), n), dtype=float, count=n)

    def values(self) -> Iterator[float]:
        """``d(0), d(1), ...`` without end (the daemon may run until a signal)."""
        s = PAPER_S0.copy()
        a = math.exp(-self.h / self.tau)
        rng = np.random.default_rng([self.seed, 0x3D1])
        gust = rng.normal(0.0, self.sigma) if self.sigma > 0 else 0.0
        while True:
            yield (PAPER_GAIN * float(s[0]) if self.oscillator else 0.0) + gust
            s = PAPER_ROTATION @ s
            if self.sigma > 0:
                gust = a * gust + math.sqrt(1 - a * a) * self.sigma * float(rng.normal())


def parse_wind_spec(text: str, h: float, seed: int = 0) -> Wind:
    """Parse a wind SPEC (module docstring); a typo is a one-line ``UserError`` quoting the SPEC."""
    def fail(why: str) -> UserError:
        return UserError(f"bad wind SPEC '{text}': {why} (expected paper, none, turbulence:SIGMA[:TAU], joined by '+')")

    oscillator, sigma, tau = False, 0.0, 2.0
    for term in text.strip().lower().split("+"):
        kind, _, rest = term.strip().partition(":")
        if kind == "none" and not rest:
            continue
        if kind == "paper" and not rest:
            oscillator = True
            continue
        if kind != "turbulence":
            raise fail(f"unknown term '{term}'")
        try:
            numbers = [float(v) for v in rest.split(":")] if rest else []
        except ValueError:
            raise fail(f"'{rest}' are not numbers") from None
        if not 1 <= len(numbers) <= 2 or not all(math.isfinite(v) and v > 0 for v in numbers):
            raise fail("turbulence takes SIGMA > 0 and optionally TAU > 0")
        sigma = numbers[0]
        tau = numbers[1] if len(numbers) == 2 else tau
    return Wind(oscillator=oscillator, sigma=sigma, tau=tau, h=h, seed=seed)
