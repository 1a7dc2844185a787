"""A proven alarm threshold: how large can |f_hat| get with no fault, from the disturbance alone?

With no fault, zero initial state and ``|d(k)| <= D``, ``f_hat = -e_f`` and, for any delay sequence,

    e_f(k) = sum_j C Phi_j B d(k - 1 - j),   Phi_j = A(tau_{k-1}) ... A(tau_{k-j})   (j factors)

so ``sup |f_hat| <= D * sum_j max |C Phi_j B|`` over every admissible sequence (the worst ``d`` takes the sign
of each term: this is the l1 norm of the time-varying impulse response). The loop is affine in ``B0(tau)``,
which lies in a polytope (``monitor.delay_model``), so ``C Phi_j B`` is multi-affine in the per-sample
convex weights and each term's largest magnitude is reached at a sequence of polytope vertices:

* **head** (j < T): every vertex sequence is enumerated (4^j of them here), the exact worst of each term;
* **tail** (j >= T): in the norm ``||x||_P`` of a Lyapunov matrix of the nominal loop, with
  ``rho = max ||product of T' vertex matrices||_P < 1`` (again a vertex maximum, by convexity),
  ``beta = max ||Phi_T B||_P`` and ``c_r = max ||C Phi_r||_P*`` (dual norm) for r < T',
  ``sum_{j >= T} |C Phi_j B| <= beta * sum_r c_r / (1 - rho)``.

Both parts are upper bounds for the polytope, hence for every delay sequence in the interval. The head is
what a constant delay can reach almost exactly, so the bound is tight where it matters: it is reported next
to the l1 norm at the worst frozen delay (a lower bound of the truth), and their ratio.

Not modelled: actuator saturation (the bound is for the linear loop; saturation only happens far above
any sensible alarm level) and sensor noise (add its contribution if the vehicle has any).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import scipy.linalg

from monitor.closed_loop import Gains, closed_loop, steady_state
from monitor.delay_model import b0_of_tau, b0_polytope, tau_grid
from monitor.errors import UserError
from monitor.plant import Plant

__all__ = ["ThresholdBound", "fault_threshold", "frozen_l1"]

HEAD = 8  # terms enumerated exactly (4^8 = 65,536 vertex sequences for a 4-vertex polytope)
BLOCKS = (1, 2, 4, 6, 8)  # tail block lengths tried; the one giving the smallest tail is kept
SEQUENCE_BUDGET = 65_536  # vertex sequences enumerated per length: V^length grows fast with the polytope
ELEMENT_BUDGET = 2**24  # floats held by one array of vertex products (134 MB)


@dataclass
class ThresholdBound:
    threshold: float  # proven sup |f_hat| for |d| <= disturbance_bound
    per_unit_disturbance: float
    disturbance_bound: float
    head: float  # per unit D: the exact worst of the first head_terms terms
    tail: float  # per unit D: the bound on the rest
    frozen_l1: float  # per unit D: l1 norm of d -> f_hat at the worst constant delay (what is actually reachable)
    tau_frozen_worst: float
    ratio_to_frozen: float
    block: int
    block_contraction: float
    head_terms: int  # how many terms were enumerated exactly (fewer when the polytope has many vertices)
    vertices: int  # of the delay polytope
    method: str = "l1 of the time-varying impulse response: vertex enumeration + Lyapunov-norm tail"

    def as_dict(self) -> dict:
        return asdict(self)


def _affordable_length(vertices: int, size: int) -> int:
    """The longest vertex sequence (at most HEAD) whose enumeration fits the budgets, at least 1.

    Why: a plant with more states or inputs has a polytope of 8, 16 or more vertices, and 16^8 products of
    its loop matrices would not fit in memory; a shorter head only makes the bound less tight, never wrong.
    """
    budget = min(SEQUENCE_BUDGET, ELEMENT_BUDGET // (size * size))
    length = 1
    while length < HEAD and vertices ** (length + 1) <= budget:
        length += 1
    return length


def _vertex_products(mats: np.ndarray, length: int) -> np.ndarray:
    """Every product of ``length`` matrices from ``mats`` (V^length of them, as one array)."""
    out = np.eye(mats.shape[1])[None]
    for _ in range(length):
        out = np.einsum("vab,nbc->vnac", mats, out).reshape(-1, *mats.shape[1:])
    return out


def frozen_l1(plant: Plant, gains: Gains, points: int = 101, horizon: int = 2000) -> tuple[float, float]:
    """``max over constant tau`` of ``sum_j sum_c max_i |C_i A^j B_c|`` (d -> f_hat); returns (value, tau)."""
    steady = steady_state(plant, gains)
    best, where = 0.0, plant.tau_min
    for tau in tau_grid(plant, points):
        loop = closed_loop(plant, gains, b0_of_tau(plant, float(tau)), steady=steady)
        x = loop.B[:, : plant.p].copy()
        total = np.zeros(loop.C_ef.shape[0])
        for _ in range(horizon):
            total += np.abs(loop.C_ef @ x).sum(axis=1)
            x = loop.A @ x
            if not np.all(np.isfinite(x)) or np.abs(x).max() < 1e-14:
                break
        if not np.all(np.isfinite(total)) or np.abs(x).max() > 1e6:
            return float("inf"), float(tau)
        if total.max() > best:
            best, where = float(total.max()), float(tau)
    return best, where


def fault_threshold(plant: Plant, gains: Gains, disturbance_bound: float) -> ThresholdBound:
    """The proven bound described in the module docstring; ``UserError`` when the loop is not provably stable."""
    if not (np.isfinite(disturbance_bound) and disturbance_bound >= 0):
        raise UserError(f"the disturbance bound must be a finite number >= 0, got {disturbance_bound}")
    gains.check_shapes(plant)
    try:
        steady = steady_state(plant, gains)
    except ValueError:
        raise UserError("no threshold: the loop has a pole at 1 (a constant fault has no steady state)") from None
    loops = [closed_loop(plant, gains, v, steady=steady) for v in b0_polytope(plant)]
    A = np.array([lp.A for lp in loops])
    B = loops[0].B[:, : plant.p]  # d columns; B does not depend on the delay
    C = loops[0].C_ef
    nominal = closed_loop(plant, gains, plant.B0, steady=steady).A
    if np.max(np.abs(np.linalg.eigvals(nominal))) >= 1.0:
        raise UserError("no threshold: the loop is unstable at the nominal delay (see fault-monitor verify)")
    head_terms = _affordable_length(len(A), A.shape[1])
    R = _lyapunov_factor(nominal)
    contracting = _contracting_blocks(A, R, head_terms)
    if not contracting:
        raise UserError(f"no threshold: the loop is not proven stable for time-varying delays (products of up to "
                        f"{head_terms} samples do not contract; see fault-monitor verify)")
    worst, head_total, tail_total, block, contraction = 0.0, 0.0, 0.0, 0, 1.0
    for c in C:  # each fault channel's |f_hat_i|; the threshold is on the largest
        head, tail, (length, rho) = _channel_bound(c, A, B, R, head_terms, contracting)
        if head + tail > worst:
            worst, head_total, tail_total, block, contraction = head + tail, head, tail, length, rho
    worst *= 1.0 + 1e-9  # floating-point slack on a sum of a few thousand terms
    l1, tau_l1 = frozen_l1(plant, gains)
    return ThresholdBound(
        threshold=worst * disturbance_bound, per_unit_disturbance=worst, disturbance_bound=float(disturbance_bound),
        head=head_total, tail=tail_total, frozen_l1=l1, tau_frozen_worst=tau_l1,
        ratio_to_frozen=worst / l1 if l1 > 0 else float("inf"), block=block, block_contraction=contraction,
        head_terms=head_terms, vertices=len(A),
    )


def _lyapunov_factor(nominal: np.ndarray) -> np.ndarray:
    """``R`` with ``||x||_P = ||R x||`` for the nominal loop's Lyapunov matrix (``A' P A - P = -I``).

    Any positive definite P gives a valid norm; this one only has to make blocks of vertex products contract.
    """
    P = scipy.linalg.solve_discrete_lyapunov(nominal.T, np.eye(nominal.shape[0]))
    try:
        return np.linalg.cholesky(0.5 * (P + P.T)).T
    except np.linalg.LinAlgError:
        raise UserError("no threshold: the nominal loop is too close to instability for a Lyapunov norm") from None


def _contracting_blocks(A: np.ndarray, R: np.ndarray, longest: int) -> list[tuple[int, float]]:
    """``(length, rho)`` for every affordable block length whose vertex products all contract in the R norm.

    The induced norm of a product is convex in each factor, so its maximum over the polytope is at vertices.
    """
    R_inv = np.linalg.inv(R)
    out = []
    for length in sorted({b for b in BLOCKS if b <= longest} | {longest}):
        rho = float(np.max(np.linalg.norm(R @ _vertex_products(A, length) @ R_inv, 2, axis=(1, 2))))
        if rho < 1.0:
            out.append((length, rho))
    return out


def _channel_bound(c: np.ndarray, A: np.ndarray, B: np.ndarray, R: np.ndarray, head_terms: int,
                   contracting: list[tuple[int, float]]) -> tuple[float, float, tuple[int, float]]:
    """``(head, tail, (block, rho))`` per unit D for one fault channel ``c``: the head exactly, the best tail."""
    R_inv = np.linalg.inv(R)
    P_inv = R_inv @ R_inv.T
    head = 0.0
    vectors = [B[:, col][None, :] for col in range(B.shape[1])]
    for _ in range(head_terms):
        head += sum(float(np.abs(v @ c).max()) for v in vectors)
        vectors = [np.einsum("vab,nb->vna", A, v).reshape(-1, A.shape[1]) for v in vectors]
    beta = sum(float(np.linalg.norm(v @ R.T, axis=1).max()) for v in vectors)
    best_tail, best_block = np.inf, (0, 1.0)
    for length, rho in contracting:
        dual = sum(float(np.sqrt(np.einsum("na,ab,nb->n", rows, P_inv, rows)).max())
                   for rows in (np.einsum("a,nab->nb", c, _vertex_products(A, r)) for r in range(length)))
        if beta * dual / (1.0 - rho) < best_tail:
            best_tail, best_block = beta * dual / (1.0 - rho), (length, rho)
    return head, best_tail, best_block
