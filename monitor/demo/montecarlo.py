"""Simulation-only runs of the paper scenario: the discrete delay-aware model, no network, many seeds.

Why a second simulator next to ``sim-vehicle``: Monte-Carlo over delay seeds needs thousands of samples
per second and no sockets. It steps the exact discrete model (``B0(tau(k))``, ``B1(tau(k))`` from
``monitor.model.delay_model``) with the same ``Estimator`` the live monitor runs, so it differs from the
live run only in what the network adds (real latency, loss). Additive faults only (bias, ramp): loss of
effectiveness and stuck act on the actuator, which only the vehicle simulator models.

The actuator is the live vehicle's: ``sim-vehicle`` clips every command to the plant's ``[actuator] limit``
(30 deg on ``paper-continuous``) and the monitor's ``Estimator`` saturates its commands at the same limit, so
the deflection that acts here is clipped the same way. Without it an unstable design's alpha grows without
bound (8e11 deg) while the live vehicle's stays within the swing the elevator's travel allows (~15 deg), and
the two tables could not be compared. A rate-limited actuator is refused: only ``sim-vehicle`` models the slew.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from monitor.checks import metrics
from monitor.model.closed_loop import Gains
from monitor.model.delay_model import b0_of_tau, input_sum
from monitor.errors import UserError
from monitor.model.estimator import Estimator
from monitor.model.plant import Plant

__all__ = ["Trace", "actuator", "simulate", "run_scenario", "monte_carlo", "Score", "score"]


@dataclass
class Trace:
    """One run, sample by sample (plant units)."""

    k: np.ndarray
    f: np.ndarray
    f_hat: np.ndarray
    alpha: np.ndarray
    q: np.ndarray
    u: np.ndarray
    tau: np.ndarray
    alarm: np.ndarray | None = None


@dataclass
class Score:
    settling_steps: int | None
    rms_ef: float | None
    peak_alpha_after: float | None
    rms_alpha_after: float | None


def actuator(plant: Plant, u: np.ndarray) -> np.ndarray:
    """The deflection that acts for command ``u``: clipped at the plant's limit, as ``sim-vehicle`` does."""
    limit = plant.actuator.limit
    return np.clip(u, -limit, limit) if limit is not None else u


def simulate(plant: Plant, gains: Gains, steps: int, fault, delay, wind_values,
             on_sample: Callable[..., None] | None = None) -> Trace:
    """Step plant + observer + controller for ``steps`` samples with delay ``delay.tau(k)`` each sample.

    ``on_sample(k, x, y, step, u, tau, f, d)``, when given, sees every sample (``api.simulate(rrd=...)``
    records them as the live monitor would).
    """
    if not fault.additive_only:
        raise UserError("the Monte-Carlo mode simulates additive faults only (bias, ramp); loe/stuck need sim-vehicle")
    if plant.actuator.rate_limit is not None:
        raise UserError("the Monte-Carlo mode does not model a rate-limited elevator; run the live demo (sim-vehicle)")
    if plant.lags is not None:
        raise UserError("the Monte-Carlo mode simulates delays within one sample; for a plant whose tau_max reaches "
                        "past h, fly sim-vehicle (it applies each command when it arrives)")
    est = Estimator(plant, gains)  # saturates its commands at the actuator limit, as the live monitor does
    state = est.initial_state()
    x = np.zeros(plant.n)
    u_prev = np.zeros(plant.m)
    Bsum = input_sum(plant)
    tau_hi = np.nextafter(plant.h, 0.0)
    out = {name: np.zeros(steps) for name in ("f", "f_hat", "alpha", "q", "u", "tau")}
    for k in range(steps):
        f = np.array(fault.f_vector(k, plant.q))
        d = np.array([next(wind_values)] + [0.0] * (plant.p - 1))
        tau = min(max(float(delay.tau(k)), 0.0), tau_hi)
        y = plant.C @ x
        step = est.step(state, k, y)
        u = actuator(plant, step.u)
        if on_sample is not None:
            on_sample(k, x, y, step, u, tau, f, d)
        B0t = b0_of_tau(plant, tau)
        out["f"][k], out["f_hat"][k], out["u"][k], out["tau"][k] = f[0], step.f_hat[0], u[0], tau
        out["alpha"][k], out["q"][k] = x[0], x[1] if plant.n > 1 else 0.0
        x = plant.A @ x + B0t @ u + (Bsum - B0t) @ u_prev + plant.Df @ f + plant.Dd @ d
        u_prev = u
    return Trace(k=np.arange(steps), **out)


def score(trace: Trace, onset: int, size: float) -> Score:
    """The comparison's figures for one run (the same functions ``replay`` uses on recordings)."""
    after = trace.k >= onset
    return Score(
        settling_steps=metrics.settling_steps(trace.k, trace.f_hat, trace.f, onset, size),
        rms_ef=metrics.rms_error(trace.k, trace.f_hat, trace.f, start=onset),
        peak_alpha_after=metrics.peak_abs(trace.alpha[after]),
        rms_alpha_after=metrics.rms(trace.alpha[after]),
    )


def run_scenario(plant: Plant, gains: Gains, steps: int, fault_spec: str, delay_spec: str, wind_spec: str,
                 seed: int, on_sample: Callable[..., None] | None = None) -> tuple[Trace, Score]:
    """One run of the scenario given as the contract's SPECs (delay and wind drawn with ``seed``), and its score."""
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec
    from sim_vehicle.wind import parse_wind_spec

    fault = parse_fault_spec(fault_spec)
    wind = parse_wind_spec(wind_spec, plant.h, seed)
    trace = simulate(plant, gains, steps, fault, parse_delay_spec(delay_spec, seed), wind.values(), on_sample)
    onset = fault.onset
    return trace, score(trace, onset if onset is not None else steps, fault.f(onset) if onset is not None else 0.0)


def monte_carlo(plant: Plant, gains: Gains, runs: int, steps: int, fault_spec: str, delay_spec: str,
                wind_spec: str, seed: int = 0) -> list[Score]:
    """``runs`` simulations with delay seeds ``seed, seed+1, ...`` (wind and fault identical)."""
    return [run_scenario(plant, gains, steps, fault_spec, delay_spec, wind_spec, seed + i)[1] for i in range(runs)]
