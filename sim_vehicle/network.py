"""Seeded emulation of an imperfect link on top of the real UDP path: loss, duplication, reordering.

Why keyed draws: the fate of datagram ``(direction, k, copy)`` is drawn from ``(seed, direction, k, copy)``,
so a run is reproducible even though the real network interleaves events differently every time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.errors import UserError

__all__ = ["Impairment", "UPLINK", "DOWNLINK"]

UPLINK = 1  # vehicle -> monitor (sensor samples)
DOWNLINK = 2  # monitor -> vehicle (commands)


@dataclass(frozen=True)
class Impairment:
    """Per-datagram probabilities; delays are in seconds of simulated time.

    ``reorder``: the datagram is held an extra ``h * U(1, 1.5)`` so the next one overtakes it (a command
    held that long misses its sampling interval, so on the downlink reordering shows up as lateness).
    ``duplicate``: a second copy follows after an extra ``h * U(0, 0.2)``.
    """

    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    h: float = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise UserError(f"--{name} must be a probability in [0, 1], got {value}")

    def fate(self, direction: int, k: int, copy: int = 0) -> list[tuple[float, str]]:
        """Extra delays of the copies that get through, each tagged ``"ok" | "reordered" | "duplicated"``.

        An empty list means the datagram is lost.
        """
        if not (self.loss or self.duplicate or self.reorder):
            return [(0.0, "ok")]  # a perfect link: every draw would say so (and costs ~60 us per datagram)
        rng = np.random.default_rng([self.seed, 0x4E7, direction, k, copy])
        lost, dup, reorder, u_reorder, u_dup = rng.random(5)
        if lost < self.loss:
            return []
        first = (self.h * (1.0 + 0.5 * u_reorder), "reordered") if reorder < self.reorder else (0.0, "ok")
        out = [first]
        if dup < self.duplicate:
            out.append((first[0] + self.h * 0.2 * u_dup, "duplicated"))
        return out
