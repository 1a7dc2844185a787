"""What a design returns: the gains, the bounds it claims, and how the solve went."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monitor.design.solve import Solved
from monitor.model.closed_loop import Gains


@dataclass
class DesignResult:
    """Gains plus the claims ``verify`` will check independently (``gamma_e``, ``gamma_z``, certificate)."""

    method: str
    gains: Gains
    gamma_e: float
    gamma_z: float
    build_seconds: float
    solve_seconds: float
    total_seconds: float
    certificate: dict[str, np.ndarray] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    bounds_apply_to: str = "real closed loop, every tau in the interval, time-varying"
    objective: str | None = None  # certified designs: "fast" or "hinf"
    max_losses: int = 0  # the certificate also covers every pattern with at most this many consecutive losses
    solved: Solved | None = None  # how the design's last LMI was solved and checked; None: no LMI (hand-written gains)
    fault_time_constant: float | None = None  # s: the reported f_hat is the estimate low-passed (None: as estimated)

    @property
    def solver_path(self) -> str:
        """One line for reports: the path that produced the accepted point and its check, or that none was solved."""
        return self.solved.describe() if self.solved is not None else "no LMI solved"
