"""How much delay can the loop take? The largest ``tau_max`` with a certified design, by bisection.

Each probe designs for the plant with the interval ``[tau_min, tau_max]`` (``monitor.model.plant.with_tau_max``)
and keeps it only when the design's certificate holds, so every point of the answer is backed by a
certificate, not by a simulation. Bisection assumes that a certifiable interval stays certifiable when
it shrinks (true of the certificate, whose polytope shrinks with it; the controller search is a
heuristic, so the curve is also sampled on a grid below the margin and reported as found).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from monitor.design import run_design
from monitor.design.result import DesignResult
from monitor.errors import DesignFailed, UserError
from monitor.model.plant import Plant, with_tau_max

__all__ = ["Margin", "delay_margin"]


@dataclass
class Margin:
    tau_max: float  # the largest certified upper delay bound found
    design: DesignResult  # the design at that bound
    plant: Plant  # the plant with that bound
    curve: list[dict[str, float]] = field(default_factory=list)  # {"tau_max", "gamma_e"}, increasing tau_max
    probes: int = 0
    no_certificate_at: float | None = None  # the smallest probed tau_max without a certificate (None: none failed)


def _try(plant: Plant, tau_max: float, options: dict[str, Any]) -> tuple[Plant, DesignResult | None]:
    variant = with_tau_max(plant, tau_max)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return variant, run_design("certified", variant, **options)
    except DesignFailed:
        return variant, None


def search_ceiling(plant: Plant, up_to: float | None = None) -> float:
    """The top of the bisection: ``up_to``, else just below h for a plant within one sample, and for a plant whose
    interval already reaches past h the most whole samples a certificate can span from its ``tau_min``."""
    if up_to is not None:
        return float(up_to)
    if plant.lags is None:
        return plant.h * (1.0 - 1e-6)
    from monitor.model.long_delay import MAX_LAG_PARTS

    return (plant.lags.first + MAX_LAG_PARTS) * plant.h * (1.0 - 1e-6)


def delay_margin(
    plant: Plant,
    tolerance: float | None = None,
    curve_points: int = 6,
    progress: Callable[[str], None] | None = None,
    up_to: float | None = None,
    **options: Any,
) -> Margin:
    """Bisection on ``tau_max`` in ``[tau_min, search_ceiling)`` to ``tolerance`` (default h/200), then the curve
    below it. Past h each probe is a lagged plant (``monitor.model.long_delay``)."""
    say = progress or (lambda _text: None)
    tol = tolerance if tolerance is not None else plant.h / 200.0
    probes = 0
    lo_plant, lo_design = _try(plant, plant.tau_min, options)
    probes += 1
    if lo_design is None:
        raise UserError(
            f"no certified design for plant '{plant.name}' even with a constant delay tau = {plant.tau_min}: "
            "no delay margin"
        )
    lo, hi = plant.tau_min, search_ceiling(plant, up_to)
    hi_plant, hi_design = _try(plant, hi, options)
    probes += 1
    if hi_design is not None:
        lo, lo_plant, lo_design = hi, hi_plant, hi_design
    while hi - lo > tol and hi_design is None:
        mid = 0.5 * (lo + hi)
        mid_plant, mid_design = _try(plant, mid, options)
        probes += 1
        say(
            f"tau_max = {mid:.4f} s: "
            + (f"certified, gamma_e = {mid_design.gamma_e:.4f}" if mid_design else "no certificate")
        )
        if mid_design is None:
            hi = mid
        else:
            lo, lo_plant, lo_design = mid, mid_plant, mid_design
    curve = []
    for i in range(curve_points):
        t = plant.tau_min + (lo - plant.tau_min) * i / max(curve_points - 1, 1)
        result: DesignResult | None
        if i == curve_points - 1:
            result = lo_design
        else:
            result = _try(plant, t, options)[1]
            probes += 1
        if result is not None:
            curve.append({"tau_max": float(t), "gamma_e": float(result.gamma_e)})
            say(f"curve: tau_max = {t:.4f} s, gamma_e = {result.gamma_e:.4f}")
    failed_at = float(hi) if hi_design is None else None
    return Margin(
        tau_max=float(lo), design=lo_design, plant=lo_plant, curve=curve, probes=probes, no_certificate_at=failed_at
    )
