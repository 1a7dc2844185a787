"""The delay margin of an envelope: each point's, found in parallel, and whether one certificate still covers them
all at the smallest.

Each point's margin is ``monitor.checks.margin.delay_margin`` on the point's own plant (its own certified design
at each probe); the points are independent searches, so they run on Dask (``monitor.parallel``). The envelope can
take no more delay than its worst point; whether it takes that much is the common certificate's question, asked
once: the whole envelope designed (``monitor.design.envelope``) with every point's interval up to the worst
point's margin. Both answers are reported: a point's margin alone says nothing about switching.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from monitor.checks.margin import delay_margin
from monitor.design.envelope import EnvelopeDesign, NoCommonCertificate, design_envelope
from monitor.model.envelope import Envelope
from monitor.model.plant import Plant, with_tau_max
from monitor.parallel import run_tasks

__all__ = ["PointMargin", "EnvelopeMargin", "envelope_margin"]


@dataclass(frozen=True)
class PointMargin:
    tau_max: float  # the point's own margin: the largest tau_max its certified design reaches
    gamma_e: float  # its design's bound there
    no_certificate_at: float | None
    probes: int


@dataclass
class EnvelopeMargin:
    points: dict[str, PointMargin]
    worst: str  # the point with the smallest margin
    tau_max: float  # that margin
    common: bool  # whether the envelope's common certificate holds with every point's interval up to it
    design: EnvelopeDesign | None = None  # the envelope designed there (None when it has no common certificate)
    why_not: str = ""
    notes: list[str] = field(default_factory=list)


def _point_margin(plant: Plant, tolerance: float | None, objective: str) -> PointMargin:
    """One point's search (module level: it runs in a Dask worker)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = delay_margin(plant, tolerance=tolerance, curve_points=2, objective=objective)
    return PointMargin(m.tau_max, m.design.gamma_e, m.no_certificate_at, m.probes)


def envelope_margin(
    envelope: Envelope,
    tolerance: float | None = None,
    objective: str = "fast",
    jobs: int = 1,
    scheduler: str | None = None,
    say: Callable[[str], None] | None = None,
) -> EnvelopeMargin:
    """Every point's margin (in parallel), the worst, and the common certificate at it (module docstring)."""
    tell = say or (lambda _text: None)

    def done(name: str, result: PointMargin, seconds: float) -> None:
        tell(f"  point '{name}': margin tau_max {result.tau_max:.4f} s ({result.probes} probes, {seconds:.1f} s)")

    tasks = [(p.name, (p.plant, tolerance, objective)) for p in envelope.points]
    points = run_tasks(_point_margin, tasks, jobs, done, scheduler, what="point '{}'")
    worst = min(points, key=lambda name: points[name].tau_max)
    tau = points[worst].tau_max
    tell(f"common certificate with every point's tau_max = {tau:.4f} s ...")
    at_margin = dataclasses.replace(
        envelope, points=tuple(dataclasses.replace(p, plant=with_tau_max(p.plant, tau)) for p in envelope.points)
    )
    options: dict[str, Any] = {"objective": objective}
    try:
        design = design_envelope(at_margin, jobs=jobs, scheduler=scheduler, **options)
    except NoCommonCertificate as exc:
        return EnvelopeMargin(points, worst, tau, False, None, str(exc))
    return EnvelopeMargin(points, worst, tau, True, design)
