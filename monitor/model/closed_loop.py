"""The real closed loop: plant with the ``u(k-1)`` state, observer (5) and controller (6), at one delay.

Why not the paper's model (9): it drops ``(B1 + B0 K2) u(k-1)`` and ``(Df + B0 K3) f`` (Lemma 3's rank
condition fails for the example) and treats ``d_tau = Delta(tau) (u(k) - u(k-1))`` as an outside input.
Here nothing is dropped. The fault is removed exactly by writing the loop in deviation from the
steady state that a constant fault produces,

    x~ = x - S_x f,   u~ = u(k-1) - S_u f,

which leaves only ``Delta f(k) = f(k+1) - f(k)`` and the disturbance ``d`` as inputs, for *any* fault
sequence. The state is ``xi = [x~; e_x; e_f; u~]`` (sizes n, n, q, m), the inputs ``w = [d; Delta f]``,
and the outputs ``e_f`` and ``y~ = C x~`` (``y = y~ + C S_x f``; ``C S_x`` is zero when K3 cancels the fault
in steady state). The loop is affine in ``B0(tau)`` because ``B0(tau) + B1(tau)`` does not depend on tau.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.model.plant import Plant

__all__ = ["Gains", "LoopMatrices", "steady_state", "fault_cancelling_K3", "closed_loop", "observer_indices"]


@dataclass(frozen=True, eq=False)
class Gains:
    """Observer (L: n x l, M: q x l) and controller (K1: m x l, K2: m x m, K3: m x q) gains."""

    L: np.ndarray
    M: np.ndarray
    K1: np.ndarray
    K2: np.ndarray
    K3: np.ndarray

    @staticmethod
    def shapes(plant: Plant) -> dict[str, tuple[int, int]]:
        """The shape each gain must have for ``plant``."""
        n, m, l, q = plant.n, plant.m, plant.l, plant.q
        return {"L": (n, l), "M": (q, l), "K1": (m, l), "K2": (m, m), "K3": (m, q)}

    @classmethod
    def zero(cls, plant: Plant, **given: np.ndarray) -> Gains:
        """Zero gains for ``plant`` except those ``given`` (the designs probe the loop, e.g. with no observer)."""
        return cls(**{name: given.get(name, np.zeros(shape)) for name, shape in cls.shapes(plant).items()})

    def check_shapes(self, plant: Plant) -> None:
        """Raise ValueError naming the first gain whose shape does not fit the plant."""
        expected = self.shapes(plant)
        for name, shape in expected.items():
            actual = getattr(self, name).shape
            if actual != shape:
                raise ValueError(
                    f"gain {name} must be {shape[0]}x{shape[1]} for this plant, got {actual[0]}x{actual[1]}"
                )


@dataclass(frozen=True)
class LoopMatrices:
    """``xi+ = A xi + B w``, ``e_f = C_ef xi``, ``y~ = C_y xi``."""

    A: np.ndarray
    B: np.ndarray
    C_ef: np.ndarray
    C_y: np.ndarray


def steady_state(plant: Plant, gains: Gains) -> tuple[np.ndarray, np.ndarray]:
    """``S_x, S_u``: the state and input that a constant unit fault settles to when the observer has converged.

    Solves ``x = A x + (B0 + B1) u + Df f`` and ``u = K1 C x + K2 u + K3 f`` (nominal delay does not
    matter: ``B0(tau) + B1(tau)`` is constant). Raises ValueError when the loop has a pole at 1.
    """
    n, m = plant.n, plant.m
    Bsum = plant.B0 + plant.B1
    lhs = np.block([[np.eye(n) - plant.A, -Bsum], [-gains.K1 @ plant.C, np.eye(m) - gains.K2]])
    rhs = np.vstack([plant.Df, gains.K3])
    try:
        sol = np.linalg.solve(lhs, rhs)
    except np.linalg.LinAlgError:
        raise ValueError("the closed loop has a pole at z = 1: no steady state for a constant fault") from None
    return sol[:n], sol[n:]


def fault_compensation(plant: Plant) -> np.ndarray:
    """The input per unit of a constant fault that leaves no steady-state output: ``u = G f`` with ``C S_x = 0``.

    With ``y = 0`` in steady state, ``u = -(C (I-A)^-1 (B0+B1))^+ C (I-A)^-1 Df f``. For an actuator fault
    (``Df = B0 + B1``) this is ``-I``: the deflection that cancels the bias at the surface. It is what a monitor
    that only compensates adds to another controller's deflection (``fault-monitor run --compensate``): any
    controller that holds ``y = 0`` without a fault then holds it with one, the fault being cancelled where it
    enters.
    """
    n = plant.n
    resolvent = np.linalg.solve(np.eye(n) - plant.A, np.hstack([plant.B0 + plant.B1, plant.Df]))
    G_u = plant.C @ resolvent[:, : plant.m]
    G_f = plant.C @ resolvent[:, plant.m :]
    u_per_f: np.ndarray = -np.linalg.pinv(G_u) @ G_f
    return u_per_f


def fault_cancelling_K3(plant: Plant, K2: np.ndarray) -> np.ndarray:
    """K3 such that a constant fault leaves no steady-state output (``C S_x = 0``), for any K1.

    The steady-state input is ``fault_compensation(plant) f``, and eq. (6) gives ``(I - K2) u = K3 f``.
    The paper's ``K3 = -B0^+ Df`` relies on Lemma 3's rank condition, which fails for its own example.
    """
    K3: np.ndarray = (np.eye(plant.m) - K2) @ fault_compensation(plant)
    return K3


def observer_indices(plant: Plant) -> tuple[slice, slice, slice, slice]:
    """Slices of ``x~, e_x, e_f, u~`` in the closed-loop state."""
    n, q, m = plant.n, plant.q, plant.m
    return slice(0, n), slice(n, 2 * n), slice(2 * n, 2 * n + q), slice(2 * n + q, 2 * n + q + m)


def closed_loop(
    plant: Plant, gains: Gains, B0_tau: np.ndarray, steady: tuple[np.ndarray, np.ndarray] | None = None
) -> LoopMatrices:
    """The closed loop at one uncertain point ``B0_tau`` (observer uses the nominal ``A, B0, B1``).

    The point is ``B0(tau)`` for an ordinary plant and the stack of curve values of a delay past one sample
    (``monitor.model.delay_model.realization`` turns it into the ``A, B0, B1`` that act). With
    ``dA, dB0, dB1`` the differences from the nominal, the observer error is driven by
    ``(dA + dB0 K1 C) x + (dB0 K2 + dB1) u(k-1) - dB0 K3 e_f``; for an ordinary plant ``dA = 0`` and
    ``dB1 = -dB0``. The constant-fault terms cancel because the steady state is the same at every point.
    """
    from monitor.model.delay_model import realization

    C, Df, Dd = plant.C, plant.Df, plant.Dd
    n, m, q, p = plant.n, plant.m, plant.q, plant.p
    L, M, K1, K2, K3 = gains.L, gains.M, gains.K1, gains.K2, gains.K3
    S_x, S_u = steady if steady is not None else steady_state(plant, gains)
    A_t, B0_t, B1_t = realization(plant, B0_tau)
    dA, dB0, dB1 = A_t - plant.A, B0_t - plant.B0, B1_t - plant.B1
    sx, se, sf, su = observer_indices(plant)
    N = 2 * n + q + m
    Acl = np.zeros((N, N))
    Acl[sx, sx] = A_t + B0_t @ K1 @ C
    Acl[sx, sf] = -B0_t @ K3
    Acl[sx, su] = B0_t @ K2 + B1_t
    Acl[se, sx] = dA + dB0 @ K1 @ C
    Acl[se, se] = plant.A - L @ C
    Acl[se, sf] = Df - dB0 @ K3
    Acl[se, su] = dB0 @ K2 + dB1
    Acl[sf, se] = -M @ C
    Acl[sf, sf] = np.eye(q)
    Acl[su, sx] = K1 @ C
    Acl[su, sf] = -K3
    Acl[su, su] = K2
    Bw = np.zeros((N, p + q))
    Bw[sx, :p] = Dd
    Bw[sx, p:] = -S_x
    Bw[se, :p] = Dd
    Bw[sf, p:] = np.eye(q)
    Bw[su, p:] = -S_u
    C_ef = np.zeros((q, N))
    C_ef[:, sf] = np.eye(q)
    C_y = np.zeros((plant.l, N))
    C_y[:, sx] = C
    return LoopMatrices(A=Acl, B=Bw, C_ef=C_ef, C_y=C_y)
