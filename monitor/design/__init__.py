"""Design methods: each module turns a plant into gains (``certified``, ``paper``, ``separate``).

One module per method so a new method is a new file, not a branch in an old one.
"""

from __future__ import annotations

from typing import Callable

from monitor.design.result import DesignResult
from monitor.plant import Plant

METHODS = ("certified", "paper", "separate")


def run_design(method: str, plant: Plant, **options) -> DesignResult:
    """Dispatch to the method's module; imported lazily because cvxpy's import costs about a second."""
    if method == "certified":
        from monitor.design.certified import design_certified as fn
    elif method == "paper":
        from monitor.design.paper import design_paper as fn
    elif method == "separate":
        from monitor.design.separate import design_separate as fn
    else:
        raise ValueError(f"unknown design method {method!r} (choose from {', '.join(METHODS)})")
    design: Callable[..., DesignResult] = fn
    return design(plant, **options)
