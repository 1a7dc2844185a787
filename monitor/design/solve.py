"""Solving an LMI problem with Clarabel and refusing anything short of an accurate optimum."""

from __future__ import annotations

import warnings

import cvxpy as cp

ACCEPTED = (cp.OPTIMAL,)


class SolveFailed(Exception):
    """The solver did not return an accurate optimum (infeasible, unbounded, inaccurate or crashed)."""


def solve_problem(problem: cp.Problem) -> str:
    """Solve with Clarabel; return the status or raise SolveFailed.

    ``optimal_inaccurate`` is refused on purpose: an inaccurate LMI solution can violate the
    inequality it claims, and a certificate that is not one is worse than none.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # cvxpy's "may be inaccurate": such results are refused below
            problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:
        raise SolveFailed(f"solver error: {exc}") from None
    if problem.status not in ACCEPTED:
        raise SolveFailed(f"solver status {problem.status}")
    return problem.status
