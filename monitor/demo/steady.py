"""Where the loop must settle once a constant fault is compensated: the caption of Fig. 5, from the model.

Why Fig. 5's pitch rate does not return to 0: the controller can only null what it measures, here
alpha (C = [1 0]). With alpha held at 0 and a constant fault f, the plant's steady state
``x = A x + (B0 + B1) u + Df f`` with ``C x = 0`` fixes both the elevator u and the unmeasured rest of the
state: n + m unknowns, n + l equations, nothing left for a design to choose. The fault enters through
``D_cf``, which is not parallel to the elevator's ``B_c``, so no deflection cancels it in both equations:
on ``paper-continuous`` a 2 deg bias leaves q = -0.579 deg/s at u = -0.880 deg. Every design whose K3
cancels the fault in the output settles there; one that does not (the paper's Lemma-3 K3) settles elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.model.plant import Plant

__all__ = ["HeldOutput", "held_output_steady_state", "constant_fault_at_end", "q_caption"]


@dataclass(frozen=True)
class HeldOutput:
    """The steady state with the measured output held at 0 against a constant fault ``f`` (plant units)."""

    f: float
    x: np.ndarray
    u: np.ndarray


def held_output_steady_state(plant: Plant, f: float) -> HeldOutput:
    """Solve ``(I - A) x - (B0 + B1) u = Df f``, ``C x = 0`` (least squares when not square)."""
    n, m = plant.n, plant.m
    fault = np.zeros(plant.q)
    fault[0] = f
    lhs = np.block([[np.eye(n) - plant.A, -(plant.B0 + plant.B1)], [plant.C, np.zeros((plant.l, m))]])
    rhs = np.concatenate([plant.Df @ fault, np.zeros(plant.l)])
    sol = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return HeldOutput(f=f, x=sol[:n], u=sol[n:])


def constant_fault_at_end(fault, steps: int) -> float | None:
    """The additive fault in force over the run's last samples when it is constant there (else None)."""
    if steps < 2 or not fault.additive_only:
        return None
    last, before = fault.f(steps - 1), fault.f(steps - 2)
    return last if last == before and last != 0.0 else None


def q_caption(plant: Plant, fault, steps: int) -> tuple[str, float | None]:
    """Fig. 5's caption and the model's steady q (None when the run ends without a constant fault)."""
    f = constant_fault_at_end(fault, steps)
    if f is None or plant.n < 2:
        return "", None
    s = held_output_steady_state(plant, f)
    q, u = float(s.x[1]), float(s.u[0])
    text = (
        "Why q settles off zero: K3 cancels the fault in the measured alpha only (C = [1 0]). "
        f"Holding alpha = 0 against f = {f:g} {plant.unit} takes\nu = {u:.2f} {plant.unit}, "
        f"and the plant's steady state then fixes q = {q:.2f} "
        f"{plant.unit}/s (dotted line): the fault enters through D_cf, not parallel to the\nelevator's B_c, so one "
        f"deflection cannot null both equations. Every design whose K3 cancels the fault settles there; the paper's "
        f"Lemma-3 K3\ndoes not, so its alpha and q settle elsewhere. q is not measured, so no design regulates it."
    )
    return text, q
