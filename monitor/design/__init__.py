"""Design methods: each module turns a plant into gains (``certified``, ``paper``, ``separate``, ``robust-separate``).

One module per method so a new method is a new file, not a branch in an old one. ``certified`` has two
objectives: ``fast`` (default, ``monitor.design.fast``) and ``hinf`` (the joint H-infinity design,
``monitor.design.certified``); both end with a common-Lyapunov certificate over the delay interval.
``monitor.design.envelope`` runs any of them at each point of an envelope (several operating points) and then
certifies the points together, with one Lyapunov matrix for every point's loop.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the CLI imports this module for METHODS and OBJECTIVES: no numpy, scipy or cvxpy at --help
    from monitor.design.result import DesignResult
    from monitor.model.plant import Plant

METHODS = ("certified", "paper", "separate", "robust-separate")
OBJECTIVES = ("fast", "hinf")
# the default design's whole time budget when it falls back to the H-infinity objective: a user who asked for
# nothing in particular gets a certified design in seconds (the H-infinity search, each candidate an LMI solve of
# seconds on a 4-state plant, stops once the budget is spent and a candidate is certified)
FALLBACK_BUDGET_S = 8.0
# the reported f_hat of a plant that flies in turbulence (its [disturbance] table names a level) is low-passed with
# this time constant by default: measured on c172p at 20 Hz over 120 s of light and moderate JSBSim turbulence, it
# takes the false alarms at a 1-deg threshold from 34 and 102 to 0 and 1, and |e_f| RMS from 0.50 to 0.29 deg (light),
# for a detection 0.6 s (light) to 1.2 s (moderate) after the onset of a 2-deg bias
# (docs/explanation/turbulence.md, the trade table)
FAULT_FILTER_S = 1.0


def default_fault_time_constant(plant: Plant, turbulence: str | None = None) -> float | None:
    """The reported estimate's low-pass by default: ``FAULT_FILTER_S`` in turbulence, none in calm air (there the
    filter would only delay the detection). The air is ``turbulence`` when given (``design --turbulence``), else
    the level the plant's ``[disturbance]`` table names (``identify --turbulence``); none named: calm."""
    level = turbulence or (plant.disturbance.turbulence if plant.disturbance is not None else None)
    return FAULT_FILTER_S if level not in (None, "none") else None


def reported_error_bound(gamma_e: float, h: float, fault_time_constant: float | None) -> float:
    """A bound on the reported estimate's error gain from ``w = [d; Delta f]``, given the loop's ``gamma_e``.

    The reported ``f_rep = LP f_hat`` with ``LP = (1 - a) / (1 - a z^-1)``, so ``f - f_rep = LP e_f + (1 - LP) f``
    and ``(1 - LP) f = a / (1 - a z^-1) Delta f``, whose gain is ``a / (1 - a)`` (at z = 1); ``|LP| <= 1``. Hence
    ``gamma_e + a / (1 - a)``: the certified loop's bound plus the filter's own lag, for every delay sequence.
    """
    from monitor.model.estimator import report_pole

    a = report_pole(h, fault_time_constant)
    return gamma_e + a / (1.0 - a)


def run_design(method: str, plant: Plant, **options: Any) -> DesignResult:
    """Dispatch to the method's module; imported lazily because cvxpy's import costs about a second."""
    objective = options.pop("objective", None)
    filtering = options.pop("fault_time_constant", None)  # None: the default for the air; 0: the raw estimate
    turbulence = options.pop("turbulence", None)  # the air the design is for (None: the plant's [disturbance] says)
    max_losses = int(options.pop("max_losses", 0) or 0)
    if max_losses:
        from monitor.model.loss_model import check_max_losses, refuse_past_one_sample

        check_max_losses(max_losses)
        refuse_past_one_sample(plant)
    if max_losses and (method, objective) in (("certified", None), ("certified", "fast")):
        options["max_losses"] = max_losses  # the fast search steers away from loss-divergent controllers
    if method == "robust-separate" and plant.lags is not None:
        from monitor.errors import UserError

        raise UserError(
            "the robust-separate method treats the delay as a B0 mismatch within one sample; this plant's "
            f"tau_max = {plant.tau_max:g} s reaches past h = {plant.h:g} s: use certified (the default)"
        )
    if objective is not None and (method != "certified" or objective not in OBJECTIVES):
        raise ValueError(
            f"objective {objective!r} applies to the certified method only (choose from {', '.join(OBJECTIVES)})"
        )
    design: Callable[..., DesignResult]
    if method == "certified" and objective in (None, "fast"):
        from monitor.design.fast import design_fast

        design = design_fast
    elif method == "certified":
        from monitor.design.certified import design_certified

        design = design_certified
    elif method == "paper":
        from monitor.design.paper import design_paper

        design = design_paper
    elif method == "separate":
        from monitor.design.separate import design_separate

        design = design_separate
    elif method == "robust-separate":
        from monitor.design.robust_separate import design_robust_separate

        design = design_robust_separate
    else:
        raise ValueError(f"unknown design method {method!r} (choose from {', '.join(METHODS)})")
    if method == "certified" and objective is None:
        result = _fast_or_hinf(plant, options)
    else:
        result = design(plant, **options)
    if max_losses:
        from monitor.design.loss_certificate import certify_losses

        result = certify_losses(result, plant, max_losses)
    result.fault_time_constant = (
        default_fault_time_constant(plant, turbulence) if filtering is None else (filtering or None)
    )
    if result.fault_time_constant:
        result.notes.append(
            f"the reported f_hat is the estimate low-passed with a {result.fault_time_constant:g}-s time constant (the "
            "loop uses the raw one, so the certificate is unchanged); its error gain is at most "
            f"{reported_error_bound(result.gamma_e, plant.h, result.fault_time_constant):.4g} (gamma_e plus the "
            "filter's lag)"
        )
    return result


def _fast_or_hinf(plant: Plant, options: dict[str, Any]) -> DesignResult:
    """The default objective: fast, and the H-infinity design when fast finds no certificate (said in the notes).

    Why: the fast objective pins the observer in closed form and searches only the controller, so on some
    plants no controller it tries has a common certificate while the joint H-infinity design, which moves
    the observer too, has one. A user who asked for nothing in particular wants a certified design.
    """
    from monitor.design.certified import design_certified
    from monitor.design.fast import design_fast
    from monitor.errors import DesignFailed

    t0 = time.perf_counter()
    try:
        return design_fast(plant, **options)
    except DesignFailed as fast_failure:
        hinf_options = {k: v for k, v in options.items() if k in ("weight_y", "progress")}
        budget = max(FALLBACK_BUDGET_S - (time.perf_counter() - t0), 0.0)
        try:
            result = design_certified(plant, time_budget_s=budget, **hinf_options)
        except DesignFailed as hinf_failure:
            raise DesignFailed(f"{fast_failure}; the H-infinity objective tried next: {hinf_failure}") from None
        result.notes.insert(
            0,
            f"the fast objective failed ({fast_failure}); fell back to the H-infinity objective "
            f"with a {FALLBACK_BUDGET_S:g}-s budget (--objective hinf searches without one)",
        )
        return result
