"""The public, notebook-sized surface of the project: ``from monitor import ...``.

Why a separate module: the commands are built from many small modules whose names are free to change;
these few functions are the promise. Each one is what a command does, without files or printing
(``design_gains`` is ``fault-monitor design``, ``check_gains`` is ``verify``, ``check_losses`` is
``verify --max-losses``):

>>> from monitor import load_plant, design_gains, check_gains, simulate
>>> plant = load_plant("paper-continuous")
>>> result = design_gains(plant)                     # the default certified design (fast objective)
>>> round(result.gamma_e, 2) <= 2.4
True
>>> check_gains(plant, result.gains).stable
True
>>> trace = simulate(plant, result.gains, fault="bias:2@20", seed=0)
>>> trace.settling_steps                          # samples after onset until |f_hat - f| <= 5 % for good
2

Plants can come from arrays (``plant_from_arrays``) or from a python-control ``StateSpace``
(``plant_from_statespace``; python-control is not a dependency), gains from a file (``read_gains``), and a
recording written by ``run``, ``analyse`` or ``demo`` is read back with ``read_recording`` (rows) or
``report`` (the scores ``replay`` prints).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from monitor.checks.verify import Verdict
from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.model.closed_loop import Gains
from monitor.model.plant import Plant, load_plant, plant_from_table
from monitor.model.simulate import Trace

if TYPE_CHECKING:  # at run time imported by the functions that return them, as the rest of this module does
    from monitor.checks.verify_losses import LossVerdict
    from monitor.service.recording_reader import Recording

__all__ = [
    "Gains",
    "Plant",
    "DesignResult",
    "Verdict",
    "SimulatedRun",
    "load_plant",
    "plant_from_arrays",
    "plant_from_statespace",
    "design_gains",
    "check_gains",
    "check_losses",
    "simulate",
    "read_gains",
    "read_recording",
    "report",
]

ArrayLike = Any  # anything numpy.asarray takes: nested lists, numpy arrays


def _rows(a: ArrayLike) -> list[list[float]]:
    rows: list[list[float]] = np.atleast_2d(np.asarray(a, dtype=float)).tolist()
    return rows


def plant_from_arrays(
    *,
    h: float,
    tau_max: float,
    tau_min: float = 0.0,
    C: ArrayLike,
    A_c: ArrayLike = None,
    B_c: ArrayLike = None,
    D_cf: ArrayLike = None,
    D_cd: ArrayLike = None,
    A: ArrayLike = None,
    B0: ArrayLike = None,
    B1: ArrayLike = None,
    Df: ArrayLike = None,
    Dd: ArrayLike = None,
    name: str = "notebook",
    actuator_limit: float | None = None,
) -> Plant:
    """A plant from matrices, validated exactly like a plant file (the same one-line errors).

    Continuous form: ``A_c, B_c, D_cf, D_cd, C`` (the simulator's kind of plant); discrete form: ``A, B0, B1,
    Df, Dd, C``. Vectors are columns: give ``B_c=[[0.0], [2.0]]`` or ``np.array([[0.0], [2.0]])``.

    >>> p = plant_from_arrays(h=1.0, tau_max=0.3, A_c=[[-1.0, 1.0], [0.0, -3.0]], B_c=[[0.0], [2.0]],
    ...                       D_cf=[[0.0], [1.0]], D_cd=[[0.5], [1.0]], C=[[1.0, 0.0]])
    >>> p.form, p.n, p.m, round(p.tau_bar, 2)
    ('continuous', 2, 1, 0.15)
    >>> slow = plant_from_arrays(h=1.0, tau_max=1.5, A_c=[[-1.0]], B_c=[[1.0]], D_cf=[[1.0]], D_cd=[[1.0]], C=[[1.0]])
    >>> slow.n, slow.physical.n  # a delay past h: the command still in flight, u(k-2), joins the state
    (2, 1)
    >>> plant_from_arrays(h=1.0, tau_min=0.5, tau_max=0.3, A_c=[[-1.0]], B_c=[[1.0]], D_cf=[[1.0]], D_cd=[[1.0]],
    ...                   C=[[1.0]])
    Traceback (most recent call last):
    ...
    monitor.errors.UserError: notebook: keys 'tau_min'/'tau_max' must satisfy 0 <= tau_min <= tau_max (got 0.5, 0.3)
    """
    table: dict[str, Any] = {
        "name": name,
        "h": float(h),
        "tau_min": float(tau_min),
        "tau_max": float(tau_max),
        "C": _rows(C),
    }
    continuous = {"A_c": A_c, "B_c": B_c, "D_cf": D_cf, "D_cd": D_cd}
    discrete = {"A": A, "B0": B0, "B1": B1, "Df": Df, "Dd": Dd}
    if all(v is not None for v in continuous.values()) and all(v is None for v in discrete.values()):
        table.update(form="continuous", **{k: _rows(v) for k, v in continuous.items()})
    elif all(v is not None for v in discrete.values()) and all(v is None for v in continuous.values()):
        table.update(form="discrete", **{k: _rows(v) for k, v in discrete.items()})
    else:
        raise UserError(
            f"{name}: give either all of A_c, B_c, D_cf, D_cd (continuous) or all of A, B0, B1, Df, Dd "
            "(discrete), not a mix"
        )
    if actuator_limit is not None:
        table["actuator"] = {"limit": float(actuator_limit)}
    return plant_from_table(table, name)


def plant_from_statespace(
    sys: Any,
    *,
    h: float,
    tau_max: float,
    tau_min: float = 0.0,
    control: Sequence[int] = (0,),
    fault: Sequence[int] = (1,),
    disturbance: Sequence[int] = (2,),
    name: str = "statespace",
    actuator_limit: float | None = None,
) -> Plant:
    """A continuous plant from a python-control ``StateSpace`` whose inputs are [controls, faults, disturbances].

    ``control``, ``fault`` and ``disturbance`` pick the input columns; ``sys.C`` is the measured output and
    ``sys.D`` must be zero (the method has no feedthrough). Anything with ``A, B, C, D`` and ``dt`` works.

    >>> class SS:  # the attributes python-control's StateSpace has (python-control itself is optional)
    ...     A = [[-1.0, 1.0], [0.0, -3.0]]; B = [[0.0, 0.0, 0.5], [2.0, 1.0, 1.0]]
    ...     C = [[1.0, 0.0]]; D = [[0.0, 0.0, 0.0]]; dt = 0
    >>> plant_from_statespace(SS(), h=1.0, tau_max=0.3).Df.shape
    (2, 1)
    """
    A, B, C, D = (np.atleast_2d(np.asarray(getattr(sys, k), dtype=float)) for k in ("A", "B", "C", "D"))
    if getattr(sys, "dt", 0) not in (0, None):
        raise UserError(
            f"{name}: a continuous-time StateSpace is needed (dt = 0), got dt = {sys.dt}; "
            "for a discrete model use plant_from_arrays(A=..., B0=..., B1=..., ...)"
        )
    if np.any(D != 0):
        raise UserError(f"{name}: the StateSpace has a feedthrough D != 0, which the method does not model")
    for label, cols in (("control", control), ("fault", fault), ("disturbance", disturbance)):
        if not cols or any(not 0 <= c < B.shape[1] for c in cols):
            raise UserError(f"{name}: {label} columns {list(cols)} are not input columns of B (it has {B.shape[1]})")
    return plant_from_arrays(
        h=h,
        tau_min=tau_min,
        tau_max=tau_max,
        A_c=A,
        B_c=B[:, list(control)],
        D_cf=B[:, list(fault)],
        D_cd=B[:, list(disturbance)],
        C=C,
        name=name,
        actuator_limit=actuator_limit,
    )


def design_gains(
    plant: Plant, method: str = "certified", objective: str | None = None, max_losses: int = 0, **options: Any
) -> DesignResult:
    """``fault-monitor design`` without the file: gains, the bounds claimed and the certificate.

    ``method``: certified (default), paper, separate, robust-separate; ``objective`` (certified only):
    fast (default) or hinf; ``max_losses``: also certify up to that many consecutive losses.
    Raises ``monitor.errors.DesignFailed`` when no certificate exists.
    """
    from monitor.design import run_design

    if objective is not None:
        options["objective"] = objective
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cvxpy's "may be inaccurate": inaccurate solves are refused anyway
        return run_design(method, plant, max_losses=max_losses, **options)


def check_gains(plant: Plant, gains: Gains, result: DesignResult | None = None) -> Verdict:
    """``fault-monitor verify``: the real loop judged from the plant and gains alone (``result`` adds its claims).

    >>> from monitor.model.closed_loop import Gains
    >>> import numpy as np
    >>> published = Gains(L=np.array([[0.0124], [-0.0008]]), M=np.array([[0.8486]]), K1=np.array([[-11.2657]]),
    ...                   K2=np.array([[-1.360]]), K3=np.array([[-0.607]]))
    >>> check_gains(load_plant("paper"), published).stable   # the paper's own gains
    False
    """
    from monitor.checks.verify import verify_gains

    if result is None:
        return verify_gains(plant, gains)
    return verify_gains(plant, gains, result.certificate or None, result.gamma_e, result.gamma_z)


def check_losses(plant: Plant, gains: Gains, max_losses: int, result: DesignResult | None = None) -> LossVerdict:
    """``verify --max-losses N``'s loss verdict (``stable`` True only with a proof; see
    monitor.checks.verify_losses)."""
    from monitor.checks.verify_losses import verify_losses

    return verify_losses(plant, gains, max_losses, result.certificate if result else None)


@dataclass
class SimulatedRun(Trace):
    """One simulated run of the loop (numpy arrays per sample, as ``Trace``) and its scores, as ``replay``
    computes them."""

    settling_steps: int | None = None
    rms_ef: float | None = None
    peak_alpha_after: float | None = None


def simulate(
    plant: Plant,
    gains: Gains,
    steps: int = 100,
    fault: str = "bias:2@20",
    delay: str | None = None,
    wind: str = "paper",
    seed: int = 0,
    rrd: str | Path | None = None,
) -> SimulatedRun:
    """Simulate plant + observer + controller (no network) with the contract's fault/delay/wind SPECs.

    ``delay`` defaults to uniform over the plant's interval. The same model as ``demo --runs``: the exact
    ``B0(tau(k))`` each sample, the monitor's own estimator, the actuator limit of the plant. With ``rrd``
    the run is also written as a recording, as ``fault-monitor run`` writes one (``report``, ``replay``,
    ``rerun FILE.rrd`` read it).
    """
    from contextlib import nullcontext

    from monitor.demo.montecarlo import score_run
    from monitor.demo.sim_recording import simulated_recording
    from monitor.model.simulate import simulate as simulate_loop
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec, parse_wind_spec

    delay_spec = delay or f"uniform:{plant.tau_min}:{plant.tau_max}"
    scenario = f"fault {fault}, delay {delay_spec}, wind {wind}, seed {seed}, {steps} samples"
    recording = (
        simulated_recording(rrd, plant, gains, "given to simulate", scenario) if rrd is not None else nullcontext(None)
    )
    with recording as on_sample:
        schedule = parse_fault_spec(fault)
        wind_values = parse_wind_spec(wind, plant.h, seed).values()
        trace = simulate_loop(plant, gains, steps, schedule, parse_delay_spec(delay_spec, seed), wind_values, on_sample)
    sc = score_run(trace, schedule)
    return SimulatedRun(
        **{f.name: getattr(trace, f.name) for f in fields(Trace)},
        settling_steps=sc.settling_steps,
        rms_ef=sc.rms_ef,
        peak_alpha_after=sc.peak_alpha_after,
    )


def read_gains(path: str | Path) -> Gains:
    """The gains of a file written by ``fault-monitor design`` (or by hand, in the contract's format)."""
    from monitor.gains import read_gains as read

    return read(path).gains


def read_recording(path: str | Path) -> Recording:
    """Every vehicle's rows of a recording (``.rrd`` from ``run``/``analyse``): ``Recording.vehicles[sysid]``."""
    from monitor.service.recording_reader import load_recording

    return load_recording(path)


def report(path: str | Path, fault: str | None = None) -> dict[str, Any]:
    """``fault-monitor replay --json`` as a dict: settling, RMS of e_f, alarms, ... of a recording."""
    from monitor.scoring import score_recording

    return score_recording(read_recording(path), fault_spec=fault)
