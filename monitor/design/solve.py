"""Solving an LMI problem and accepting its result by what it claims, never by the solver's status word.

Why: the status word depends on the last digits of the data. The same LMI that Clarabel calls ``optimal``
on one CPU it calls ``optimal_inaccurate`` on another (or on the plant perturbed at 1e-9), although the
point it returns satisfies every inequality with room to spare; and ``optimal`` does not promise that the
point satisfies the strict inequality a certificate needs. So every solve here goes through
:func:`solve_checked`:

1. the problem is posed well: every strict inequality ``F < 0`` is written ``F <= -EPS I`` (an explicit
   strictness ``EPS``), so "holds" has a size the check below can demand;
2. each path of :data:`PATHS` is tried in turn: Clarabel as configured by default; Clarabel on the same
   constraints with a small trace penalty on the Lyapunov matrices, which keeps the variables bounded and
   the optimum interior (a hard bound ``trace X <= 1e5`` broke Clarabel on a preset's certificate:
   measured, so the bound is a penalty); a stronger penalty; then SCS, the other conic solver cvxpy installs;
3. a result is accepted when the caller's ``claim`` -- an independent numpy re-evaluation of the
   inequalities that the design relies on, at the returned point and with the gains recovered from it --
   holds with a margin of at least ``CHECK_MARGIN``, whatever the status word; it is refused when it does
   not, even after ``optimal``.

The :class:`Solved` record names the path that produced the accepted point; designs put it in their report
and gains file.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # cvxpy costs about a second to import: only the solves load it, not `import monitor.design`
    import cvxpy as cp

__all__ = [
    "EPS",
    "CHECK_MARGIN",
    "PATHS",
    "SEARCH_PATHS",
    "SolvePath",
    "Solved",
    "SolveFailed",
    "solve_checked",
    "most_positive_eigenvalue",
    "value_of",
]

EPS = 1e-6  # every strict LMI F < 0 is posed as F <= -EPS I
CHECK_MARGIN = 0.5 * EPS  # the numpy check accepts F <= -CHECK_MARGIN I: half the posed strictness, far above rounding


class SolveFailed(Exception):
    """No path produced a point whose claim holds (infeasible, unbounded, inaccurate beyond use, or crashed)."""


@dataclass(frozen=True)
class SolvePath:
    """One way to solve: a cvxpy solver, its settings, and optionally a regularised objective.

    ``regularise``: minimise ``objective + regularise * sum(trace X)`` over the problem's matrix variables
    (the Lyapunov matrices, positive definite in every LMI here). The constraints are untouched, so any point
    it finds proves what the original proves, with bounds larger by a hair; the penalty keeps the variables
    bounded and the optimum interior, where the plain problem's optimum sits on a face the interior-point
    method approaches too slowly (measured: Clarabel's ``InsufficientProgress`` on a certificate LMI that
    this path solves with the same bound to 5 digits).
    """

    name: str
    solver: str
    options: dict[str, Any] = field(default_factory=dict)
    regularise: float = 0.0

    def problem_for(self, problem: cp.Problem) -> cp.Problem:
        """The problem this path solves; a regularised variant is built once per problem and kept on it.

        Kept because a problem with parameters (the H-infinity design's inner LMI, re-solved for every
        controller candidate) is compiled once by cvxpy and then only re-filled: a variant built afresh at
        each solve would be compiled again each time (seconds on a 4-state aircraft model).
        """
        import cvxpy as cp

        if not self.regularise:
            return problem
        variants: dict[float, cp.Problem] = problem.__dict__.setdefault("_regularised_variants", {})
        if self.regularise not in variants:
            traces = [cp.trace(v) for v in problem.variables() if v.ndim == 2 and v.is_symmetric()]
            variants[self.regularise] = (
                problem
                if not traces
                else cp.Problem(
                    cp.Minimize(problem.objective.expr + self.regularise * cp.sum(cp.hstack(traces))),
                    problem.constraints,
                )
            )
        return variants[self.regularise]


PATHS: tuple[SolvePath, ...] = (
    SolvePath("clarabel", "CLARABEL"),
    SolvePath("clarabel-regularised", "CLARABEL", regularise=1e-4),
    SolvePath("clarabel-regularised-strong", "CLARABEL", {"max_iter": 400}, regularise=1e-2),
    # Last resort, with a bounded number of iterations: SCS is first-order, slower and less accurate on these
    # LMIs, so its point is often refused by the check; it is there for a Clarabel that fails outright.
    SolvePath("scs", "SCS", {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 5_000}),
)
SEARCH_PATHS = PATHS[:2]  # inside searches over many candidates: no slow last resort for each failing one


@dataclass(frozen=True)
class Solved:
    """The accepted point's provenance: which path, the solver's own word, and the margin the check found."""

    path: str
    status: str
    margin: float

    def describe(self) -> str:
        return (
            f"{self.path} ({self.status}); every LMI re-checked in numpy holds with margin {self.margin:.2e} "
            f">= {CHECK_MARGIN:.0e}"
        )


def value_of(expr: cp.Expression) -> np.ndarray:
    """``expr.value`` after a solve; TypeError when the solver left none (inside a claim: the point proves nothing)."""
    value = expr.value
    if value is None:
        raise TypeError(f"{expr} has no value: the problem was not solved")
    return value


def most_positive_eigenvalue(M: np.ndarray) -> float:
    """Largest eigenvalue of the symmetric part: ``F <= -m I`` holds exactly when this is ``<= -m``."""
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1])


def solve_checked(
    problem: cp.Problem,
    claim: Callable[[], float],
    *,
    paths: tuple[SolvePath, ...] = PATHS,
    retry_infeasible: bool = True,
) -> Solved:
    """Solve ``problem`` along ``paths`` until ``claim()`` holds; return how, or raise SolveFailed naming each try.

    ``claim()`` reads the variables' values and returns the smallest margin by which the inequalities the
    design relies on hold (``-most_positive_eigenvalue`` of each ``F <= 0``); it may raise (a singular slack
    matrix, missing values) to say that the point proves nothing. ``retry_infeasible=False`` stops at a path
    that reports infeasibility: inside a search over many candidates, where a wrongly refused candidate only
    steers the search, the second and third paths would multiply the cost of every infeasible one.
    """
    import cvxpy as cp

    tries: list[str] = []
    for path in paths:
        attempt = path.problem_for(problem)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # cvxpy's "may be inaccurate": the claim below decides
                attempt.solve(solver=path.solver, **path.options)
        except (cp.error.SolverError, ArithmeticError, ValueError) as exc:
            tries.append(f"{path.name}: solver error ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")
            continue
        status = str(attempt.status)
        if status in (cp.INFEASIBLE, cp.UNBOUNDED) and not retry_infeasible:
            tries.append(f"{path.name}: {status}")
            break
        value = attempt.value
        margin = _margin(claim) if value is not None and np.isfinite(value) else -np.inf
        if margin >= CHECK_MARGIN:
            return Solved(path=path.name, status=status, margin=margin)
        tries.append(
            f"{path.name}: {status}"
            + (f", check failed (margin {margin:.1e} < {CHECK_MARGIN:.0e})" if np.isfinite(margin) else "")
        )
    raise SolveFailed("; ".join(tries))


def _margin(claim: Callable[[], float]) -> float:
    """The claim's margin, or -inf when it cannot be evaluated (singular recovery, missing or non-finite values)."""
    try:
        with np.errstate(all="ignore"):
            margin = float(claim())
    except (np.linalg.LinAlgError, TypeError, ValueError, AttributeError):
        return -np.inf
    return margin if np.isfinite(margin) else -np.inf
