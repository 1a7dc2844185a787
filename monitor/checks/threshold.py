"""A proven alarm threshold: how large can |f_hat| get with no fault, from the disturbance alone?

With no fault, zero initial state and ``|d(k)| <= D``, ``f_hat = -e_f`` and, for any delay sequence,

    e_f(k) = sum_j C Phi_j B d(k - 1 - j),   Phi_j = A(tau_{k-1}) ... A(tau_{k-j})   (j factors)

so ``sup |f_hat| <= D * sum_j max |C Phi_j B|`` over every admissible sequence (the worst ``d`` takes the sign
of each term: this is the l1 norm of the time-varying impulse response). The loop is affine in ``B0(tau)``,
which lies in a polytope (``monitor.model.delay_model``), so ``C Phi_j B`` is multi-affine in the per-sample
convex weights and each term's largest magnitude is reached at a sequence of polytope vertices:

* **head** (j < T): every vertex sequence is enumerated (4^j of them here), the exact worst of each term;
* **tail** (j >= T): in the norm ``||x||_P`` of a Lyapunov matrix of the nominal loop, with
  ``rho = max ||product of T' vertex matrices||_P < 1`` (again a vertex maximum, by convexity),
  ``beta = max ||Phi_T B||_P`` and ``c_r = max ||C Phi_r||_P*`` (dual norm) for r < T',
  ``sum_{j >= T} |C Phi_j B| <= beta * sum_r c_r / (1 - rho)``.

Both parts are upper bounds for the polytope, hence for every delay sequence in the interval ("blocks").

A second proof ("paths") uses that every term of e_f(k) sees the *same* delay sequence: it is the largest
``sum_j |r_j B|_1`` along one vertex path of rows ``r_{j+1} = r_j A_i`` from ``r_0 = c`` (a sum of convex functions
of each step's convex weights, so again a vertex maximum), searched worst-first, with a cost-to-go from a common
quadratic norm in which every vertex contracts (an LMI solved with Clarabel, its contraction and constants then
recomputed in numpy, so the solver is never trusted). The smaller of the two is the threshold; either is a proof.
The head is what a constant delay can reach almost exactly, so the bound is tight where it matters: it is
reported next to the l1 norm at the worst frozen delay (a lower bound of the truth), and their ratio.

Not modelled: actuator saturation (the bound is for the linear loop; saturation only happens far above
any sensible alarm level) and sensor noise (add its contribution if the vehicle has any).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import scipy.linalg

from monitor.errors import UserError
from monitor.model.closed_loop import Gains, closed_loop, steady_state
from monitor.model.delay_model import b0_of_tau, b0_polytope, nominal_point, tau_grid
from monitor.model.norms import dual_norms, induced_norms, norm_factor
from monitor.model.plant import Plant

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
    frozen_l1: float  # per unit D: l1 norm of d -> f_hat at the worst constant delay (what is actually reachable)
    tau_frozen_worst: float
    ratio_to_frozen: float
    method: str  # the proof that gave the (smaller) bound: "paths" or "blocks"
    bound_paths: float | None  # per unit D: best-first vertex paths + common quadratic cost-to-go (None: no such norm)
    bound_blocks: float | None  # per unit D: per-term vertex enumeration + block tail (None: blocks do not contract)
    ellipsoid: float | None  # per unit D: the common quadratic norm alone (the invariant-ellipsoid bound), for scale
    common_rate: float | None  # the contraction of every vertex in that norm, re-checked in numpy
    path_depth: int  # every delay path was followed exactly at least this many samples
    head_terms: int  # terms enumerated exactly by the block proof (fewer when the polytope has many vertices)
    block: int
    block_contraction: float
    vertices: int  # of the delay polytope
    seconds: float

    def as_dict(self) -> dict[str, Any]:
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
    nominal = closed_loop(plant, gains, nominal_point(plant), steady=steady).A
    if np.max(np.abs(np.linalg.eigvals(nominal))) >= 1.0:
        raise UserError("no threshold: the loop is unstable at the nominal delay (see fault-monitor verify)")
    started = time.perf_counter()
    head_terms = _affordable_length(len(A), A.shape[1])
    contracting = _contracting_blocks(A, _lyapunov_factor(nominal), head_terms)
    channels = [_channel_proofs(c, A, B, nominal, head_terms, contracting) for c in C]
    proven = [ch for ch in channels if ch["bound"] is not None]
    if len(proven) < len(channels):
        raise UserError(
            "no threshold: the loop is not proven stable for time-varying delays (no common quadratic "
            f"norm contracts, nor products of up to {head_terms} samples; see fault-monitor verify)"
        )
    worst = max(proven, key=lambda ch: ch["bound"])  # the threshold is on the largest |f_hat_i|
    per_unit = worst["bound"] * (1.0 + 1e-9)  # floating-point slack on sums of thousands of terms
    l1, tau_l1 = frozen_l1(plant, gains)
    return ThresholdBound(
        threshold=per_unit * disturbance_bound,
        per_unit_disturbance=per_unit,
        disturbance_bound=float(disturbance_bound),
        frozen_l1=l1,
        tau_frozen_worst=tau_l1,
        ratio_to_frozen=per_unit / l1 if l1 > 0 else float("inf"),
        method=worst["method"],
        bound_paths=worst["paths"],
        bound_blocks=worst["blocks"],
        ellipsoid=worst["ellipsoid"],
        common_rate=worst["rate"],
        path_depth=worst["depth"],
        head_terms=head_terms,
        block=worst["block"],
        block_contraction=worst["contraction"],
        vertices=len(A),
        seconds=time.perf_counter() - started,
    )


def _channel_proofs(
    c: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    nominal: np.ndarray,
    head_terms: int,
    contracting: list[tuple[int, float]],
) -> dict[str, Any]:
    """Both proofs for one fault channel; ``bound`` is the smaller (either is a proof on its own)."""
    out: dict[str, Any] = {
        "blocks": None,
        "paths": None,
        "ellipsoid": None,
        "rate": None,
        "depth": 0,
        "block": 0,
        "contraction": 1.0,
    }
    if contracting:
        head, tail, (out["block"], out["contraction"]) = _channel_bound(
            c, A, B, _lyapunov_factor(nominal), head_terms, contracting
        )
        out["blocks"] = head + tail
    norm = _common_norm(A, B, c)
    if norm is not None:
        R, out["rate"], gamma = norm
        out["ellipsoid"] = gamma * float(dual_norms(c, R)[0])
        out["paths"], out["depth"] = _best_first_bound(A, B, c, R, gamma)
    found: dict[str, float] = {k: out[k] for k in ("paths", "blocks") if out[k] is not None}
    out["method"] = min(found, key=found.__getitem__) if found else None
    out["bound"] = found[out["method"]] if found else None
    return out


def _lyapunov_factor(nominal: np.ndarray) -> np.ndarray:
    """``R`` with ``||x||_P = ||R x||`` for the nominal loop's Lyapunov matrix (``A' P A - P = -I``).

    Any positive definite P gives a valid norm; this one only has to make blocks of vertex products contract.
    """
    R = norm_factor(scipy.linalg.solve_discrete_lyapunov(nominal.T, np.eye(nominal.shape[0])))
    if R is None:
        raise UserError("no threshold: the nominal loop is too close to instability for a Lyapunov norm")
    return R


def _contracting_blocks(A: np.ndarray, R: np.ndarray, longest: int) -> list[tuple[int, float]]:
    """``(length, rho)`` for every affordable block length whose vertex products all contract in the R norm.

    The induced norm of a product is convex in each factor, so its maximum over the polytope is at vertices.
    """
    out = []
    for length in sorted({b for b in BLOCKS if b <= longest} | {longest}):
        rho = float(np.max(induced_norms(R, _vertex_products(A, length))))
        if rho < 1.0:
            out.append((length, rho))
    return out


def _channel_bound(
    c: np.ndarray, A: np.ndarray, B: np.ndarray, R: np.ndarray, head_terms: int, contracting: list[tuple[int, float]]
) -> tuple[float, float, tuple[int, float]]:
    """``(head, tail, (block, rho))`` per unit D for one fault channel ``c``: the head exactly, the best tail."""
    head = 0.0
    vectors = [B[:, col][None, :] for col in range(B.shape[1])]
    for _ in range(head_terms):
        head += sum(float(np.abs(v @ c).max()) for v in vectors)
        vectors = [np.einsum("vab,nb->vna", A, v).reshape(-1, A.shape[1]) for v in vectors]
    beta = sum(float(np.linalg.norm(v @ R.T, axis=1).max()) for v in vectors)
    best_tail, best_block = np.inf, (0, 1.0)
    for length, rho in contracting:
        dual = sum(float(dual_norms(np.einsum("a,nab->nb", c, _vertex_products(A, r)), R).max()) for r in range(length))
        if beta * dual / (1.0 - rho) < best_tail:
            best_tail, best_block = beta * dual / (1.0 - rho), (length, rho)
    return head, best_tail, best_block


# --- along one delay path: a quadratic cost-to-go and best-first search -------------------------------------
#
# All terms of e_f(k) share one delay sequence, so the exact quantity is a maximum over paths of rows
# r_0 = c, r_{j+1} = r_j A(tau_{k-1-j}), of sum_j |r_j B|_1. A norm ||r||_* = sqrt(r P^-1 r') in which every
# vertex contracts by rho gives the cost-to-go g(r) = beta ||r||_* / (1 - rho), beta = sum_col ||B_col||_P,
# which satisfies g(r) >= |r B|_1 + g(r A_i): so s + g(r) never grows along a path, and the largest of it over
# any frontier that every path crosses is a proof. Expanding the worst frontier node first tightens it.

RHO_FRACTIONS = (0.02, 0.3, 0.6, 0.85)  # rho tried between the best common rate and 1
RATE_BISECTIONS = 9
EXPANSIONS = 20_000  # frontier nodes expanded per fault channel (best first)


def _common_norm(A: np.ndarray, B: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """``(R, rho, gamma)`` with ``||x||_P = ||R x||``, every ``||R A_i R^-1|| <= rho < 1`` and ``g(c) = gamma ||c||_*``.

    P comes from an LMI (common ``A_i' P A_i <= rho^2 P``, the shape that makes ``g(c)`` smallest), solved with
    Clarabel (``solve_checked``: accepted by its contraction re-evaluated in numpy); nothing else the solver says is
    trusted either: rho and beta are recomputed in numpy from the P it returns.
    None when no common quadratic norm contracts (then the block bound is used).
    """
    import cvxpy as cp

    from monitor.design.solve import EPS, SolveFailed, solve_checked, value_of

    N = A.shape[1]
    rho2 = cp.Parameter(nonneg=True)
    P = cp.Variable((N, N), symmetric=True)
    contract = [(rho2 - EPS) * P - Ai.T @ P @ Ai >> 0 for Ai in A]  # strict by EPS, relative to P's own scale
    rate = cp.Problem(cp.Minimize(0), [P >> np.eye(N), cp.trace(P) <= 1e4 * N, *contract])

    def contracts() -> float:  # rho^2 - max ||R A_i R^-1||^2 with P = R'R: how strictly every vertex contracts
        R = norm_factor(0.5 * (value_of(P) + value_of(P).T))
        return -np.inf if R is None else float(value_of(rho2) - np.max(induced_norms(R, A)) ** 2)

    lo, hi = 0.0, 1.0
    for _ in range(RATE_BISECTIONS):  # the smallest common rate, to about 2^-RATE_BISECTIONS
        rho2.value = (0.5 * (lo + hi)) ** 2
        try:
            solve_checked(rate, contracts, retry_infeasible=False)
            hi = 0.5 * (lo + hi)
        except SolveFailed:
            lo = 0.5 * (lo + hi)
    if hi >= 1.0:
        return None
    t = cp.Variable((1, 1))
    shape = cp.Problem(
        cp.Minimize(t),
        [
            P >> 1e-6 * np.eye(N),
            cp.bmat([[t, c[None, :]], [c[:, None], P]]) >> 0,
            cp.sum([cp.quad_form(B[:, k], P) for k in range(B.shape[1])]) <= 1.0,
            *contract,
        ],
    )

    def bound(norm: tuple[np.ndarray, float, float]) -> float:  # g(c) = gamma ||c||_*
        return norm[2] * float(dual_norms(c, norm[0])[0])

    best = None
    for fraction in RHO_FRACTIONS:
        rho2.value = (hi + fraction * (1.0 - hi)) ** 2
        try:
            solve_checked(shape, contracts, retry_infeasible=False)
        except SolveFailed:
            continue
        candidate = _checked_norm(P.value, A, B)
        if candidate is not None and (best is None or bound(candidate) < bound(best)):
            best = candidate
    return best


def _checked_norm(P: np.ndarray | None, A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """``(R, rho, gamma)`` recomputed in numpy from a proposed P, or None when it is no contracting norm."""
    R = norm_factor(P)
    if R is None:
        return None
    rho = float(np.max(induced_norms(R, A)))
    if not rho < 1.0:
        return None
    beta = float(np.linalg.norm(R @ B, axis=0).sum())
    return R, rho, beta / (1.0 - rho)


def _best_first_bound(
    A: np.ndarray, B: np.ndarray, c: np.ndarray, R: np.ndarray, gamma: float, budget: int = EXPANSIONS
) -> tuple[float, int]:
    """``(bound, depth)``: max of ``s + gamma ||r||_*`` over a frontier grown worst-node-first from the root c.

    Each node is a vertex path: its row r and the sum s of ``|r_j B|_1`` so far. The returned depth is the
    shallowest frontier node's, i.e. every path was followed exactly at least that far.
    """
    import heapq

    heap = [(-gamma * float(dual_norms(c, R)[0]), 0, 0.0, c, 0)]
    counter = 1
    for _ in range(budget):
        _, _, s, r, depth = heapq.heappop(heap)
        s_child = s + float(np.abs(r @ B).sum())
        rows = np.einsum("a,vab->vb", r, A)
        for row, value in zip(rows, s_child + gamma * dual_norms(rows, R), strict=True):
            heapq.heappush(heap, (-float(value), counter, s_child, row, depth + 1))
            counter += 1
    return -heap[0][0], min(node[4] for node in heap)
