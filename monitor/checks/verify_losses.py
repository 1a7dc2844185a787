"""``verify --max-losses N``: is the loop stable for every pattern of at most N consecutive losses? (numpy only)

Two kinds of evidence, kept apart so the verdict can never call a divergent loop stable:

* **Divergence search** (lower bounds of the switched loop's growth rate): every macro-step (j <= N
  losses of either kind, then a delivered sample; ``monitor.model.loss_model``) at a dense grid of delays,
  its spectral radius per sample; and long renormalised products of adversarial and random patterns:
  alternating delivered/lost, bursts of exactly N losses of each kind and mixed, random admissible
  patterns, with the delay at the interval's ends or random. Any growth >= 1 is a pattern that diverges.
* **Proof** (an upper bound < 1): a norm in which every macro-step at every vertex of a polytope that
  contains the delay curve is a contraction (or every product of two macro-steps is). The norm is
  ``||x||_P = sqrt(x^T P x)`` with P the certificate's ``P_loss`` when the gains file carries one
  (re-checked here, not trusted), else P from the averaged Lyapunov equation, else the identity. A
  macro-step at any delay is a convex combination of the vertex ones and a norm is convex, so the
  contraction holds for every delay sequence.

``stable`` is True only with a proof, False when a divergent pattern was found, None when neither. When
the gains file carries no P_loss, verify also searches a candidate P itself (an LMI feasibility problem);
whatever its origin, a P counts only through the numpy contraction check above.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from monitor.model.closed_loop import Gains, closed_loop, steady_state
from monitor.model.delay_model import b0_of_tau, b0_polytope, tau_grid
from monitor.model.loss_model import check_max_losses, loss_modes, loss_sequences, macro_step_growth, macro_steps
from monitor.model.norms import contraction
from monitor.model.plant import Plant

__all__ = ["LossVerdict", "verify_losses"]


@dataclass
class LossVerdict:
    max_losses: int
    stable: bool | None
    growth_lower_bound: float  # worst growth per sample found (>= 1: diverges)
    worst_pattern: str
    proof: str  # which norm proved it, or why there is no proof
    contraction: float | None  # the proven per-macro-step contraction factor, when proven

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _pattern_growth(matrices: list[np.ndarray], sequence: list[int]) -> float:
    """Per-sample growth of ``||M_sequence ... M_1||`` (renormalised, so long products do not overflow)."""
    V = np.eye(matrices[0].shape[0])
    log_growth = 0.0
    for j in sequence:
        V = matrices[j] @ V
        s = np.linalg.norm(V, 2)
        if not np.isfinite(s) or s == 0.0:
            return float("inf") if not np.isfinite(s) else 0.0
        log_growth += np.log(s)
        V /= s
    return float(np.exp(log_growth / len(sequence)))


def _divergence_search(
    plant: Plant,
    gains: Gains,
    steady: tuple[np.ndarray, np.ndarray],
    max_losses: int,
    rng: np.random.Generator,
    steps: int = 1200,
) -> tuple[float, str]:
    """The worst growth per sample over macro-steps on a delay grid and over long adversarial/random patterns."""
    taus = tau_grid(plant, 21)
    growth = macro_step_growth(plant, gains, [b0_of_tau(plant, float(t)) for t in taus], max_losses, steady)
    i, j = np.unravel_index(int(np.argmax(growth)), growth.shape)
    seq = loss_sequences(max_losses)[j]
    worst = float(growth[i, j])
    where = f"repeat [{' '.join(('lost ' + k) for k in seq) or 'no loss'}; delivered at tau={taus[i]:.4f}]"
    modes = loss_modes(plant, gains)
    delivered = [closed_loop(plant, gains, b0_of_tau(plant, float(t)), steady=steady).A for t in taus]
    mats = delivered + [modes["sample"], modes["command"]]
    S_i, C_i, ends = len(delivered), len(delivered) + 1, (0, len(delivered) - 1)
    patterns: dict[str, list[int]] = {}
    for n in range(1, max_losses + 1):
        for name, run in (
            ("lost samples", [S_i] * n),
            ("lost commands", [C_i] * n),
            ("mixed losses", [S_i if j % 2 else C_i for j in range(n)]),
        ):
            for end in ends:
                patterns[f"bursts of {n} {name}, delivered at tau={taus[end]:.4f}"] = ([end] + run) * (steps // (n + 1))
            patterns[f"bursts of {n} {name}, delivered at alternating ends"] = sum(
                ([ends[b % 2]] + run for b in range(steps // (n + 1))), []
            )
    for label in ("random delays", "random ends"):
        drawn: list[int] = []
        streak = 0
        for _ in range(steps):
            if streak < max_losses and rng.random() < 0.5:
                drawn.append(S_i if rng.random() < 0.5 else C_i)
                streak += 1
            else:
                drawn.append(
                    int(rng.integers(len(delivered))) if label == "random delays" else ends[int(rng.integers(2))]
                )
                streak = 0
        patterns[f"random losses (<= {max_losses} in a row), {label}"] = drawn
    for name, pattern in patterns.items():
        rate = _pattern_growth(mats, pattern)
        if rate > worst:
            worst, where = rate, name
    return worst, where


def _averaged_lyapunov(steps: list[np.ndarray], iterations: int = 500) -> np.ndarray | None:
    """P solving ``P = I + mean_i S_i^T P S_i`` by fixed-point iteration; None when it does not converge."""
    N = steps[0].shape[0]
    P = np.eye(N)
    for _ in range(iterations):
        nxt: np.ndarray = np.eye(N) + sum(S.T @ P @ S for S in steps) / len(steps)
        if not np.all(np.isfinite(nxt)):
            return None
        if np.linalg.norm(nxt - P) <= 1e-10 * np.linalg.norm(nxt):
            return nxt
        P = nxt
    return None


def _searched_norm(plant: Plant, gains: Gains, vertices: list[np.ndarray], max_losses: int) -> np.ndarray | None:
    """A candidate P from a Lyapunov LMI over the macro-steps; only a candidate: ``contraction`` decides."""
    from monitor.design.loss_certificate import loss_certificate  # cvxpy: imported only when needed

    return loss_certificate(plant, gains, vertices, max_losses)


def verify_losses(
    plant: Plant, gains: Gains, max_losses: int, certificate: dict[str, np.ndarray] | None = None, seed: int = 0
) -> LossVerdict:
    """The verdict described in the module docstring."""
    check_max_losses(max_losses)
    gains.check_shapes(plant)
    try:
        steady = steady_state(plant, gains)
    except ValueError:
        steady = (np.zeros((plant.n, plant.q)), np.zeros((plant.m, plant.q)))
    growth, pattern = _divergence_search(plant, gains, steady, max_losses, np.random.default_rng(seed))
    if growth >= 1.0:
        return LossVerdict(max_losses, False, growth, pattern, "none: a pattern diverges", None)
    vertices = b0_polytope(plant)
    steps = macro_steps(plant, gains, vertices, max_losses, steady)
    candidates: list[tuple[str, Any]] = []  # (name, P or a function making it: found lazily, cheapest first)
    if certificate and "P_loss" in certificate and certificate["P_loss"].shape == steps[0].shape:
        candidates.append(("the certificate's P_loss", certificate["P_loss"]))
    candidates += [
        ("P of the averaged Lyapunov equation", lambda: _averaged_lyapunov(steps)),
        ("the identity", lambda: np.eye(steps[0].shape[0])),
        (
            "a P verify searched itself (LMI feasibility, re-checked here)",
            lambda: _searched_norm(plant, gains, vertices, max_losses),
        ),
    ]
    for depth in (1, 2):
        for name, make in candidates:
            P = make() if callable(make) else make
            if P is None:
                continue
            factor = contraction(P, steps, depth)
            if factor < 1.0:
                what = "every macro-step" if depth == 1 else "every product of two macro-steps"
                proof = (
                    f"{what} at all {len(vertices)} polytope vertices contracts in the norm of {name} "
                    f"(factor {factor:.4f} < 1)"
                )
                return LossVerdict(max_losses, True, growth, pattern, proof, factor)
    return LossVerdict(
        max_losses,
        None,
        growth,
        pattern,
        "no divergent pattern found, but no norm proved contraction either: not proven",
        None,
    )
