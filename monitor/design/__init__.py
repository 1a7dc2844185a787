"""Design methods: each module turns a plant into gains (``certified``, ``paper``, ``separate``, ``robust-separate``).

One module per method so a new method is a new file, not a branch in an old one. ``certified`` has two
objectives: ``fast`` (default, ``monitor.design.fast``) and ``hinf`` (the joint H-infinity design,
``monitor.design.certified``); both end with a common-Lyapunov certificate over the delay interval.
"""

from __future__ import annotations

from typing import Callable

from monitor.design.result import DesignResult
from monitor.plant import Plant

METHODS = ("certified", "paper", "separate", "robust-separate")
OBJECTIVES = ("fast", "hinf")


def run_design(method: str, plant: Plant, **options) -> DesignResult:
    """Dispatch to the method's module; imported lazily because cvxpy's import costs about a second."""
    objective = options.pop("objective", None)
    max_losses = int(options.pop("max_losses", 0) or 0)
    if max_losses:
        from monitor.loss_model import check_max_losses

        check_max_losses(max_losses)
    if max_losses and (method, objective) in (("certified", None), ("certified", "fast")):
        options["max_losses"] = max_losses  # the fast search steers away from loss-divergent controllers
    if objective is not None and (method != "certified" or objective not in OBJECTIVES):
        raise ValueError(f"objective {objective!r} applies to the certified method only (choose from {', '.join(OBJECTIVES)})")
    if method == "certified" and objective in (None, "fast"):
        from monitor.design.fast import design_fast as fn
    elif method == "certified":
        from monitor.design.certified import design_certified as fn
    elif method == "paper":
        from monitor.design.paper import design_paper as fn
    elif method == "separate":
        from monitor.design.separate import design_separate as fn
    elif method == "robust-separate":
        from monitor.design.robust_separate import design_robust_separate as fn
    else:
        raise ValueError(f"unknown design method {method!r} (choose from {', '.join(METHODS)})")
    design: Callable[..., DesignResult] = fn
    result = design(plant, **options)
    if max_losses:
        from monitor.design.loss_certificate import certify_losses

        result = certify_losses(result, plant, max_losses)
    return result
