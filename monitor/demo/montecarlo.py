"""The demo's Monte Carlo over delay seeds (``fault-monitor demo --runs``) and the scores of a simulated run.

The simulation is the model core's (``monitor.model.simulate``: the exact discrete delay-aware model, the
monitor's own ``Estimator``, the live vehicle's actuator limit); here the contract's fault/delay/wind SPECs are
parsed (``monitor.wire.specs``), a run is flown per seed and scored with the functions ``replay`` uses on
recordings.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from monitor.checks import metrics
from monitor.model.closed_loop import Gains
from monitor.model.plant import Plant
from monitor.model.simulate import Trace, simulate
from monitor.wire.specs import FaultSchedule, parse_delay_spec, parse_fault_spec, parse_wind_spec

# Trace is the model core's (monitor.model.simulate); named here too for the demo's figures and report
__all__ = ["Trace", "run_scenario", "monte_carlo", "Score", "score", "score_run"]


@dataclass
class Score:
    settling_steps: int | None
    rms_ef: float | None
    peak_alpha_after: float | None
    rms_alpha_after: float | None


def score(trace: Trace, onset: int, size: float) -> Score:
    """The comparison's figures for one run (the same functions ``replay`` uses on recordings)."""
    after = trace.k >= onset
    return Score(
        settling_steps=metrics.settling_steps(trace.k, trace.f_hat, trace.f, onset, size),
        rms_ef=metrics.rms_error(trace.k, trace.f_hat, trace.f, start=onset),
        peak_alpha_after=metrics.peak_abs(trace.alpha[after]),
        rms_alpha_after=metrics.rms(trace.alpha[after]),
    )


def score_run(trace: Trace, fault: FaultSchedule) -> Score:
    """``score`` against the run's own fault: from its onset and at its size there (no fault: from the end, 0)."""
    onset = fault.onset
    return score(trace, onset if onset is not None else len(trace.k), fault.f(onset) if onset is not None else 0.0)


def run_scenario(
    plant: Plant,
    gains: Gains,
    steps: int,
    fault_spec: str,
    delay_spec: str,
    wind_spec: str,
    seed: int,
    on_sample: Callable[..., None] | None = None,
) -> tuple[Trace, Score]:
    """One run of the scenario given as the contract's SPECs (delay and wind drawn with ``seed``), and its score."""
    fault = parse_fault_spec(fault_spec)
    wind = parse_wind_spec(wind_spec, plant.h, seed)
    trace = simulate(plant, gains, steps, fault, parse_delay_spec(delay_spec, seed), wind.values(), on_sample)
    return trace, score_run(trace, fault)


def monte_carlo(
    plant: Plant, gains: Gains, runs: int, steps: int, fault_spec: str, delay_spec: str, wind_spec: str, seed: int = 0
) -> list[Score]:
    """``runs`` simulations with delay seeds ``seed, seed+1, ...`` (wind and fault identical)."""
    return [run_scenario(plant, gains, steps, fault_spec, delay_spec, wind_spec, seed + i)[1] for i in range(runs)]
