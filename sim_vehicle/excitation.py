"""``--excite prbs:AMP:SECONDS``: an identification manoeuvre on the elevator, flown open loop about trim.

As an autopilot's system-identification mode does, the vehicle itself issues the elevator: a seeded random
binary sequence of trim +- AMP (plant units, degrees) for the first SECONDS, then the trim deflection once
(the manoeuvre ends where it started), and from then on it holds trim or follows commands from outside.

The dwell (the time between two switches) is drawn uniformly from [0.2 s, 0.8 s], whole samples, at least
one sample. Why: a switch every 0.2-0.8 s (mean 0.5 s) puts the sequence's power flat from DC to about
1/(pi * 0.5 s) = 0.6 Hz, falling off above: it covers the short period (c172p at 100 kt: a 1-2 Hz mode that
settles in ~0.6 s) and, for runs of a few minutes, the phugoid (~25 s period) too; a fixed-clock PRBS would
have to pick one bit length for both. The draws come from ``(seed, "excite")`` only, so the same seed gives
the same manoeuvre whatever the link does.

Each level is issued at its sample k and applied after the drawn delay tau(k), like ``--autopilot``'s
commands, and the sample's ACTUATOR_OUTPUT_STATUS reports the deflection issued (the contract's observe-only
meaning), so a tlog of the run holds input and output side by side for ``fault-monitor analyse``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monitor.errors import UserError

__all__ = ["Excitation", "parse_excite_spec", "MIN_DWELL_S", "MAX_DWELL_S"]

MIN_DWELL_S = 0.2
MAX_DWELL_S = 0.8


@dataclass(frozen=True)
class Excitation:
    """A PRBS of +-``amplitude`` about trim for ``seconds`` of simulated time."""

    amplitude: float
    seconds: float

    def samples(self, h: float) -> int:
        """How many samples carry a PRBS level (the next one returns to trim)."""
        return max(1, int(round(self.seconds / h)))

    def signs(self, h: float, seed: int) -> list[int]:
        """+1/-1 per sample for ``samples(h)`` samples: seeded random switching with dwell in [0.2, 0.8] s."""
        n = self.samples(h)
        rng = np.random.default_rng([seed, 0xE7C1])
        shortest = max(1, int(math.ceil(MIN_DWELL_S / h - 1e-9)))
        longest = max(shortest, int(math.floor(MAX_DWELL_S / h + 1e-9)))
        sign = 1 if rng.random() < 0.5 else -1
        out: list[int] = []
        while len(out) < n:
            out.extend([sign] * int(rng.integers(shortest, longest + 1)))
            sign = -sign
        return out[:n]

    def __str__(self) -> str:
        return f"prbs:{self.amplitude:g}:{self.seconds:g}"


def parse_excite_spec(text: str | None) -> Excitation | None:
    """``prbs:AMP:SECONDS`` (AMP degrees > 0, SECONDS > 0) -> ``Excitation``; None or "none" -> None."""
    if text is None or str(text).strip().lower() in ("", "none"):
        return None
    kind, _, rest = str(text).strip().lower().partition(":")
    parts = rest.split(":")
    try:
        numbers = [float(v) for v in parts]
    except ValueError:
        numbers = []
    if kind != "prbs" or len(numbers) != 2 or not all(math.isfinite(v) and v > 0 for v in numbers):
        raise UserError(f"bad --excite SPEC '{text}': expected prbs:AMP:SECONDS with AMP (deg) and SECONDS > 0, "
                        "e.g. prbs:1:60")
    return Excitation(amplitude=numbers[0], seconds=numbers[1])
