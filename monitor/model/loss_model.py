"""The real closed loop when the network loses samples or commands: a switched system with three modes.

The contract's link events (CONTRACT.md, "What the estimator uses"), in the coordinates of
``monitor.model.closed_loop`` (``xi = [x~; e_x; e_f; u~]``, deviations from the constant-fault steady state):

* **delivered** (``closed_loop`` at ``B0(tau)``): the command for k acts after ``tau(k) < h``;
* **command lost or late**: the actuator holds ``u(k-1)`` the whole period; the estimator, told so by the
  next report, steps with the held deflection (``monitor.model.estimator``), so its error sees no delay mismatch:
  ``x~+ = A x~ + (B0+B1) u~``, ``e_x+ = (A - L C) e_x + Df e_f``, ``e_f+ = e_f - M C e_x``, ``u~+ = u~``;
* **sample lost**: no command, the actuator holds, the estimator predicts without innovation:
  ``e_x+ = A e_x + Df e_f``, ``e_f+ = e_f``; the plant part as above.

Neither loss mode depends on the delay, and both have an eigenvalue 1 (the held actuator, and for a lost
sample the frozen fault estimate), so no loop is stable under losses alone: what can be certified is a
bound N on **consecutive losses of either kind**. Every admissible sequence is then a product of
*macro-steps* ``D(tau) X_j ... X_1`` (j <= N losses, each X a lost sample or a lost command, then a
delivered sample), and ``D`` is affine in ``B0(tau)``, so a macro-step at any delay is a convex
combination of the macro-steps at the vertices of a polytope that contains the delay curve.
"""

from __future__ import annotations

import itertools

import numpy as np

from monitor.model.closed_loop import Gains, closed_loop, observer_indices
from monitor.model.plant import Plant

__all__ = [
    "refuse_past_one_sample",
    "loss_modes",
    "loss_sequences",
    "macro_steps",
    "macro_step_growth",
    "check_max_losses",
    "LOSS_KINDS",
    "MAX_LOSSES",
]

LOSS_KINDS = ("sample", "command")
MAX_LOSSES = 8  # 2^(N+1) - 1 loss runs per delay vertex: N = 8 is ~2,000 LMI blocks, a few tens of seconds


def check_max_losses(max_losses: int) -> int:
    """The N of ``--max-losses``, refused with one line when negative or beyond what can be certified in time."""
    from monitor.errors import UserError

    if not 0 <= max_losses <= MAX_LOSSES:
        raise UserError(
            f"--max-losses must be between 0 and {MAX_LOSSES} (every run of up to N losses is "
            f"enumerated: 2^(N+1) - 1 of them), got {max_losses}"
        )
    return max_losses


def refuse_past_one_sample(plant: Plant) -> None:
    """Losses are certified for delays within one sample only: say so in one line for a lagged plant.

    Why: a lost or late command here means "the actuator holds u(k-1) the whole interval"; past one sample a
    late command still acts when it arrives (the link rule of ``monitor.model.long_delay``), so the loss
    modes above are not what happens, and no certificate of them would be sound.
    """
    if plant.lags is not None:
        from monitor.errors import UserError

        raise UserError(
            f"--max-losses is certified for delays within one sample (tau_max < h); this plant's "
            f"tau_max = {plant.tau_max:g} s reaches past h = {plant.h:g} s, where a late command still "
            f"acts on arrival: certify the delay alone (without --max-losses)"
        )


def loss_modes(plant: Plant, gains: Gains) -> dict[str, np.ndarray]:
    """The state matrices of a lost sample and of a lost (or late) command; the inputs do not matter here."""
    refuse_past_one_sample(plant)
    A, C, Df = plant.A, plant.C, plant.Df
    Bsum = plant.B0 + plant.B1
    sx, se, sf, su = observer_indices(plant)
    N = su.stop
    base = np.zeros((N, N))
    base[sx, sx] = A
    base[sx, su] = Bsum
    base[se, se] = A
    base[se, sf] = Df
    base[sf, sf] = np.eye(plant.q)
    base[su, su] = np.eye(plant.m)
    sample = base.copy()
    command = base.copy()
    command[se, se] = A - gains.L @ C
    command[sf, se] = -gains.M @ C
    return {"sample": sample, "command": command}


def loss_sequences(max_losses: int) -> list[tuple[str, ...]]:
    """Every run of 0..N losses between two delivered samples, each loss of either kind."""
    return [seq for j in range(max_losses + 1) for seq in itertools.product(LOSS_KINDS, repeat=j)]


def macro_steps(
    plant: Plant, gains: Gains, b0_points: list[np.ndarray], max_losses: int, steady: tuple[np.ndarray, np.ndarray]
) -> list[np.ndarray]:
    """``D(B0) X_j ... X_1`` for every loss run of length <= N and every ``B0`` given (vertices or a grid)."""
    modes = loss_modes(plant, gains)
    runs = []
    for seq in loss_sequences(max_losses):
        product = np.eye(modes["sample"].shape[0])
        for kind in seq:
            product = modes[kind] @ product
        runs.append(product)
    delivered = [closed_loop(plant, gains, b0, steady=steady).A for b0 in b0_points]
    return [D @ run for D in delivered for run in runs]


def macro_step_growth(
    plant: Plant, gains: Gains, b0_points: list[np.ndarray], max_losses: int, steady: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Growth per sample, ``rho(S) ** (1 / (j + 1))``, of every macro-step: ``[b0 point, loss run]`` in the order
    of ``b0_points`` and ``loss_sequences``. Above 1 anywhere: that pattern, repeated, diverges (a lower bound)."""
    steps = np.array(macro_steps(plant, gains, b0_points, max_losses, steady))
    samples = np.array([len(seq) + 1 for seq in loss_sequences(max_losses)])
    radii = np.max(np.abs(np.linalg.eigvals(steps)), axis=-1).reshape(len(b0_points), len(samples))
    growth: np.ndarray = radii ** (1.0 / samples)
    return growth
