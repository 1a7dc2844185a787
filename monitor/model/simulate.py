"""The one discrete closed-loop simulator: plant + the monitor's estimator/controller over delays, faults and wind.

Why a simulator next to ``sim-vehicle``: Monte-Carlo over delay seeds needs thousands of samples per second and
no sockets. It steps the exact discrete model (``B0(tau(k))``, ``B1(tau(k))`` from ``monitor.model.delay_model``)
with the same ``Estimator`` the live monitor runs, so it differs from the live run only in what the network adds
(real latency, loss). Additive faults only (bias, ramp): loss of effectiveness and stuck act on the actuator,
which only the vehicle simulator models. ``fault-monitor demo --runs`` (``monitor.demo.montecarlo``) and the
public ``monitor.simulate`` both run it.

The actuator is the live vehicle's: ``sim-vehicle`` clips every command to the plant's ``[actuator] limit``
(30 deg on ``paper-continuous``) and the monitor's ``Estimator`` saturates its commands at the same limit, so
the deflection that acts here is clipped the same way. Without it an unstable design's alpha grows without
bound (8e11 deg) while the live vehicle's stays within the swing the elevator's travel allows (~15 deg), and
the two tables could not be compared. A rate-limited actuator is refused: only ``sim-vehicle`` models the slew.

Pure: numpy only, no sockets, files or clocks. The fault, the delay and the wind come in already parsed
(``monitor.wire.specs``: a ``FaultSchedule``, a ``DelaySampler`` and the values of a ``Wind``), so reading a
``trace:FILE`` delay SPEC stays with the caller.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from monitor.errors import UserError
from monitor.model.closed_loop import Gains
from monitor.model.delay_model import b0_of_tau, input_sum
from monitor.model.estimator import Estimator
from monitor.model.plant import Plant

if TYPE_CHECKING:
    from monitor.wire.specs import DelaySampler, FaultSchedule

__all__ = ["Trace", "actuator", "simulate"]


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


def actuator(plant: Plant, u: np.ndarray) -> np.ndarray:
    """The deflection that acts for command ``u``: clipped at the plant's limit, as ``sim-vehicle`` does."""
    limit = plant.actuator.limit
    return np.clip(u, -limit, limit) if limit is not None else u


def simulate(
    plant: Plant,
    gains: Gains,
    steps: int,
    fault: FaultSchedule,
    delay: DelaySampler,
    wind_values: Iterator[float],
    on_sample: Callable[..., None] | None = None,
) -> Trace:
    """Step plant + observer + controller for ``steps`` samples with delay ``delay.tau(k)`` each sample.

    ``wind_values`` yields ``d(k)`` on the plant's first wind input (``Wind.values()``).
    ``on_sample(k, x, y, step, u, tau, f, d)``, when given, sees every sample (``api.simulate(rrd=...)``
    records them as the live monitor would).
    """
    if not fault.additive_only:
        raise UserError("the Monte-Carlo mode simulates additive faults only (bias, ramp); loe/stuck need sim-vehicle")
    if plant.actuator.rate_limit is not None:
        raise UserError("the Monte-Carlo mode does not model a rate-limited elevator; run the live demo (sim-vehicle)")
    if plant.lags is not None:
        raise UserError(
            "the Monte-Carlo mode simulates delays within one sample; for a plant whose tau_max reaches "
            "past h, fly sim-vehicle (it applies each command when it arrives)"
        )
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
