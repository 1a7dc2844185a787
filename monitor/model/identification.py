"""A continuous plant from a flight's samples: operating point, least squares, free-run validation, modes.

Input: the samples of one vehicle on the sampling grid ``k h`` (sample indices ``k``, every state measured, in
plant units, and the elevator deflection the vehicle reported, absolute). Output: ``x' = A_c x + B_c u`` in
deviations from the operating point, how well it predicts data it was not fitted on, and its modes.

The method, and why:

* **Where the excitation is.** The elevator's spread over the log must be at least ``MIN_SPREAD`` (0.1 deg), or
  there is nothing to identify from. A sample is *quiet* when the elevator is within a quarter of that spread of
  where it rests; a quiet run of at least ``QUIET_S`` (2 s, longer than any dwell of a PRBS) at the start is the
  lead-in, one at the end the tail, and the excitation is what lies between. It must last ``MIN_EXCITATION_S``.
* **Operating point.** With a lead-in (the flight-test habit: trimmed flight, then the manoeuvre) it is the mean
  of every signal over the last ``LEAD_IN_S`` of it: measured trim. Without one (``sim-vehicle --excite`` starts
  the manoeuvre at once and returns to trim after it), the elevator's trim is its mean over the tail (where it
  sits at its trim value), else the mean over the excitation, and the states' trim is the **equilibrium of the
  fitted model** at that elevator: the fit gets a constant term, and ``x* = (I - A_d)^-1 (B_d u* + c)``. A state
  mean over the manoeuvre would not do: the aircraft is still in its phugoid when the tail starts.
* **Fit, in two steps.** Every state is measured, so the discrete model ``x(k+1) = A_d x(k) + B_d u(k)`` (the
  elevator held over a sample, as the vehicle's servo holds it) is linear in its parameters: ordinary least squares
  over the pairs of consecutive samples (equation error), columns scaled to unit spread, is the first estimate.
  It is biased by sensor noise, because the noisy measured state is also the regressor (measured on the c172p of
  ``tests/test_identify.py`` with white noise of 0.05 deg on alpha and theta, 0.2 deg/s on q, 0.1 m/s on airspeed:
  the phugoid came out as two real roots, theta's held-out fit 8 %). So it is then refined by **output error**:
  ``scipy.optimize.least_squares`` (Levenberg-Marquardt) minimises the free-run error of the model over the fitted
  part, each output weighted by its spread, with the initial state (and, without a lead-in, a constant offset of
  the operating point) as extra parameters. A free run does not feed the noise back in, so the estimate is not
  biased by it (the same noisy flight: phugoid 25.8 s, zeta 0.12; short period within 2 % of JSBSim's
  linearisation). Free runs are cheap in modal coordinates (``simulate``), so the refinement takes about a
  second on a minute of flight. A refinement that does not lower the cost, or whose A_d has no real logarithm,
  is dropped for the least-squares model (said in ``notes``).
* **Continuous time.** ``A_c = logm(A_d) / h`` and ``B_c = Gamma(h)^-1 B_d``
  (``monitor.model.discretize.reconstruct_continuous``), after checking that A_d has no eigenvalue on the closed
  negative real axis (no real logarithm) and that the logarithm found is real and gives A_d back.
* **Why no identification library.** Subspace methods (nfoursid, SIPPY) estimate a state basis, which is
  pointless when the states are the measurements and would hide the physical coordinates the plant file needs;
  python-control has no estimator. Least squares plus a bounded output-error refinement is ~60 lines on numpy
  and scipy, which the project already depends on.
* **Validation.** The first 70 % of the excitation (and the lead-in) are fitted, the last 30 % held out: the model
  runs **free** from the measured state at the start of the held-out part, driven only by the measured elevator,
  and ``fit = 100 (1 - ||y - y_hat|| / ||y - mean y||)`` per output (NRMSE; 100 is perfect, 0 is no better than
  the mean). One-step prediction errors are not used: with states 1/20 s apart any model predicts one step well.

Pure functions of arrays: no files, no clocks. ``monitor.pipelines.identify_log`` reads the log and writes the
file, whose text is ``monitor.model.plant_toml``'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from monitor.errors import UserError
from monitor.model.discretize import integral_expm, reconstruct_continuous

__all__ = [
    "HOLDOUT",
    "MIN_EXCITATION_S",
    "MIN_SPREAD",
    "MODELS",
    "FlightData",
    "Identification",
    "IdentificationError",
    "Mode",
    "identify",
    "modes_of",
    "nrmse_fit",
    "gust_from_residual",
    "finite_or_none",
    "simulate",
]

MODELS: dict[str, tuple[str, ...]] = {
    "short-period": ("alpha", "q"),
    "longitudinal": ("alpha", "q", "theta", "airspeed"),
}
MIN_SPREAD = 0.1  # deg: an elevator that moves less than this over the log is no excitation
QUIET_FRACTION = 0.25  # of the spread: within this of its resting value the elevator is quiet
QUIET_S = 2.0  # a quiet run at least this long at the start (end) is a lead-in (tail), not a PRBS dwell
LEAD_IN_S = 10.0  # the operating point is the mean of at most the last this-many seconds of the lead-in
MIN_EXCITATION_S = 10.0
MIN_PAIRS_PER_PARAMETER = 10
HOLDOUT = 0.3


class IdentificationError(UserError):
    """A log identify cannot work from; the message is one line starting with the reason."""


@dataclass(frozen=True)
class FlightData:
    """One vehicle's samples: ``k`` (sample indices, increasing), ``states`` (N x n), ``inputs`` (N x m)."""

    h: float
    k: np.ndarray
    states: np.ndarray
    inputs: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...] = ("elevator",)
    state_units: tuple[str, ...] = ()


@dataclass(frozen=True)
class Mode:
    """A pair of eigenvalues of A_c: a damped oscillation (complex pair) or two real roots (``oscillatory`` False)."""

    name: str
    eigenvalues: tuple[complex, complex]
    wn: float  # rad/s (sqrt of the product of the roots)
    zeta: float
    oscillatory: bool

    @property
    def period_s(self) -> float | None:
        wd = abs(self.eigenvalues[0].imag)
        return 2 * math.pi / wd if self.oscillatory and wd > 0 else None

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "wn_rad_s": self.wn,
            "zeta": self.zeta,
            "period_s": self.period_s,
            "oscillatory": self.oscillatory,
            "eigenvalues": [[float(e.real), float(e.imag)] for e in self.eigenvalues],
        }

    def describe(self) -> str:
        if not math.isfinite(self.wn):
            roots = ", ".join(f"{e.real:.4g}" for e in self.eigenvalues)
            return f"{self.name}: real roots {roots} 1/s (one unstable)"
        text = f"{self.name}: wn {self.wn:.4g} rad/s, zeta {self.zeta:.3f}"
        if self.period_s is not None:
            text += f", period {self.period_s:.3g} s"
        elif not self.oscillatory:
            text += " (two real roots: not oscillatory)"
        return text


@dataclass
class Identification:
    """What ``identify`` found; matrices in deviations from ``operating_point`` (plant units)."""

    h: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    operating_point: dict[str, float]
    operating_point_source: str
    A_d: np.ndarray
    B_d: np.ndarray
    A_c: np.ndarray
    B_c: np.ndarray
    fit_validation: dict[str, float]
    fit_estimation: dict[str, float]
    modes: list[Mode]
    samples: int  # samples in the log (assembled)
    samples_estimation: int  # pairs of consecutive samples fitted
    samples_validation: int  # samples the free run is scored on
    excitation: dict[str, float]  # start_s, end_s, seconds, elevator spread (deg)
    validation_span_s: tuple[float, float]
    validation_run: dict[str, np.ndarray] = field(default_factory=dict, repr=False)  # t, y, y_hat (for plots)
    method: dict[str, Any] = field(default_factory=dict)  # least squares, and the output-error refinement's figures
    notes: list[str] = field(default_factory=list)
    disturbance: dict[str, float] | None = None  # the gust the flight met: sigma, time_constant (gust_from_residual)

    def report(self) -> dict[str, Any]:
        """A JSON-friendly summary (``fault-monitor identify --json``): strict JSON, a non-finite number is null."""
        report: dict[str, Any] = finite_or_none(
            {
                "h": self.h,
                "states": list(self.state_names),
                "inputs": list(self.input_names),
                "operating_point": dict(self.operating_point),
                "operating_point_source": self.operating_point_source,
                "fit_percent": dict(self.fit_validation),
                "fit_percent_estimation": dict(self.fit_estimation),
                "modes": [m.as_dict() for m in self.modes],
                "A_c": self.A_c.tolist(),
                "B_c": self.B_c.tolist(),
                "samples": {
                    "log": self.samples,
                    "estimation_pairs": self.samples_estimation,
                    "validation": self.samples_validation,
                },
                "excitation": dict(self.excitation),
                "validation_span_s": list(self.validation_span_s),
                "method": dict(self.method),
                "disturbance": self.disturbance,
                "notes": list(self.notes),
            }
        )
        return report


def finite_or_none(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    return value


def nrmse_fit(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """Per column: ``100 (1 - ||y - y_hat|| / ||y - mean y||)`` (-inf when y does not vary)."""
    y = np.asarray(y, float)
    y_hat = np.asarray(y_hat, float)
    err = np.linalg.norm(y - y_hat, axis=0)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spread > 0, 100.0 * (1.0 - err / np.where(spread > 0, spread, 1.0)), -np.inf)


def modes_of(A_c: np.ndarray) -> list[Mode]:
    """The eigenvalues in pairs, fastest first: 2 states -> the short period; 4 -> short period and phugoid.

    Pairing by magnitude keeps a complex pair together (equal magnitudes) and splits a quartic into the two
    quadratics the longitudinal modes are; for another number of states the extra roots form their own modes.
    """
    eig = np.linalg.eigvals(A_c)
    order = np.argsort(-np.abs(eig), kind="stable")
    eig = eig[order]
    names = {1: ["short period"], 2: ["short period", "phugoid"]}.get(len(eig) // 2) or [
        f"mode {i + 1}" for i in range(len(eig) // 2)
    ]
    modes: list[Mode] = []
    for i, name in enumerate(names):
        a, b = complex(eig[2 * i]), complex(eig[2 * i + 1])
        oscillatory = abs(a.imag) > 1e-12 and abs(a.imag + b.imag) < 1e-9 * max(1.0, abs(a))
        if oscillatory:
            a, b = (a, b) if a.imag > 0 else (b, a)
            wn = abs(a)
            zeta = -a.real / wn
        else:
            a, b = complex(a.real, 0.0), complex(b.real, 0.0)
            product = a.real * b.real
            wn = math.sqrt(product) if product > 0 else float("nan")
            zeta = -(a.real + b.real) / (2 * wn) if product > 0 else float("nan")
        modes.append(Mode(name, (a, b), float(wn), float(zeta), oscillatory))
    if len(eig) % 2:
        e = complex(eig[-1])
        modes.append(Mode("real root", (e, e), abs(e.real), 1.0 if e.real < 0 else -1.0, False))
    return modes


def _runs(quiet: np.ndarray) -> tuple[int, int]:
    """Length of the quiet run at the start and at the end of a boolean array."""
    n = len(quiet)
    lead = n if quiet.all() else int(np.argmin(quiet))
    tail = n if quiet.all() else int(np.argmin(quiet[::-1]))
    return lead, tail


def _excitation_window(t: np.ndarray, u: np.ndarray, name: str) -> tuple[int, int, int, int, float]:
    """``(start, end, lead, tail, spread)``: excitation in ``[start, end)``; lead-in ``[0, start)`` if ``lead``."""
    spread = float(np.ptp(u)) if len(u) else 0.0
    seconds = float(t[-1] - t[0]) if len(t) else 0.0
    if spread < MIN_SPREAD:
        level = f" of {float(np.median(u)):.3f} deg" if len(u) else ""
        raise IdentificationError(
            f"no excitation: the {name} stays within {spread:.3f} deg{level} over the {len(u)} samples "
            f"({seconds:.1f} s) of the log (identify needs it moved by at least {MIN_SPREAD} deg, e.g. a PRBS "
            "of +-1 deg for a minute: sim-vehicle run --excite prbs:1:60)"
        )
    threshold = QUIET_FRACTION * spread
    lead, _ = _runs(np.abs(u - u[0]) <= threshold)
    _, tail = _runs(np.abs(u - u[-1]) <= threshold)
    n = len(u)
    start = lead if lead < n and t[lead - 1] - t[0] >= QUIET_S - 1e-9 and lead > 0 else 0
    end = n - tail if tail < n and t[-1] - t[n - tail] >= QUIET_S - 1e-9 and tail > 0 else n
    if end <= start:  # cannot happen with spread > 0, but never return an empty window
        start, end = 0, n
    return start, end, start, n - end, spread


def _lstsq(phi: np.ndarray, target: np.ndarray, names: list[str]) -> np.ndarray:
    """Least squares with each regressor scaled to unit spread; a column that never moves is named."""
    scale = phi.std(axis=0)
    for i, s in enumerate(scale):
        if not s > 1e-12 * max(1.0, float(np.abs(phi[:, i]).max(initial=0.0))):
            if names[i] == "1":
                scale[i] = 1.0
                continue
            raise IdentificationError(
                f"no excitation: {names[i]} does not move over the fitted samples "
                "(a constant regressor cannot be told from the others)"
            )
    theta, _, rank, sv = np.linalg.lstsq(phi / scale, target, rcond=None)
    if rank < phi.shape[1] or sv[-1] < 1e-9 * sv[0]:
        raise IdentificationError(
            f"no excitation: the fitted samples do not tell {', '.join(n for n in names if n != '1')} apart "
            f"(regressor condition number {sv[0] / max(sv[-1], 1e-300):.3g}); fly a richer manoeuvre"
        )
    scaled: np.ndarray = theta / scale[:, None]
    return scaled


def _free_run_loop(A_d: np.ndarray, B_d: np.ndarray, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """States of ``x(k+1) = A_d x + B_d u(k)`` from ``x0``, one step at a time (row i is x at step i)."""
    out = np.empty((len(u), A_d.shape[0]))
    x = np.asarray(x0, dtype=float)
    bu = u @ B_d.T
    for i in range(len(u)):
        out[i] = x
        x = A_d @ x + bu[i]
    return out


def simulate(A_d: np.ndarray, B_d: np.ndarray, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The free run ``x(k+1) = A_d x + B_d u(k)`` from ``x0`` over the rows of ``u`` (row i is x at step i).

    In modal coordinates each mode is a first-order recursion, which ``scipy.signal.lfilter`` runs in C:
    ~1 ms for 10,000 samples instead of ~30 ms stepping in Python; this is what makes the output-error fit's
    hundreds of free runs cheap. A nearly defective A (ill-conditioned eigenvectors) is stepped directly.
    """
    with np.errstate(all="ignore"):
        lam, V = np.linalg.eig(A_d)
        if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > 1e8:
            return _free_run_loop(A_d, B_d, x0, u)
        W = np.linalg.inv(V)
        w = (W @ B_d) @ u.T
        z0 = W @ np.asarray(x0, dtype=float)
        z = np.empty((len(lam), len(u)), dtype=complex)
        for i, root in enumerate(lam):
            z[i] = lfilter([0.0, 1.0], [1.0, -root], w[i], zi=[z0[i]])[0]
        return (V @ z).real.T


def _output_error(
    A_d: np.ndarray, B_d: np.ndarray, y: np.ndarray, u: np.ndarray, offset: bool, max_iterations: int = 40
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]] | None:
    """Refine ``(A_d, B_d)`` to the smallest free-run error over ``y`` (grid rows, NaN where missing), each output
    weighted by its spread; the initial state is a parameter, and with ``offset`` a constant offset of the
    measurements too (the operating point, when it is not measured). None when the refinement does not improve.
    """
    n, m = B_d.shape
    present = ~np.isnan(y).any(axis=1)
    yp = y[present]
    scale = yp.std(axis=0)
    scale[~(scale > 0)] = 1.0
    sizes = (n * n, n * m, n, n if offset else 0)
    cuts = np.cumsum(sizes)

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        A, B = p[: cuts[0]].reshape(n, n), p[cuts[0] : cuts[1]].reshape(n, m)
        x0, d = p[cuts[1] : cuts[2]], (p[cuts[2] : cuts[3]] if offset else np.zeros(n))
        return A, B, x0, d

    def residual(p: np.ndarray) -> np.ndarray:
        A, B, x0, d = unpack(p)
        with np.errstate(all="ignore"):
            r = ((yp - d - simulate(A, B, x0, u)[present]) / scale).ravel()
        finite: np.ndarray = np.nan_to_num(r, nan=1e6, posinf=1e6, neginf=-1e6)
        return finite

    first = int(np.argmax(present))
    p0 = np.concatenate([A_d.ravel(), B_d.ravel(), y[first] if first == 0 else np.zeros(n), np.zeros(sizes[3])])
    cost0 = 0.5 * float(residual(p0) @ residual(p0))
    try:
        sol = least_squares(residual, p0, method="lm", x_scale="jac", max_nfev=max_iterations * (len(p0) + 1))
    except (ValueError, np.linalg.LinAlgError):
        return None
    if not (np.isfinite(sol.cost) and sol.cost < cost0):
        return None
    A, B, _x0, d = unpack(sol.x)
    return A, B, d, {"cost_least_squares": cost0, "cost": float(sol.cost), "evaluations": int(sol.nfev)}


def _grid(k: np.ndarray, values: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """``values`` on the full index grid ``lo .. hi - 1`` (rows of missing samples are NaN)."""
    out = np.full((hi - lo, values.shape[1]), np.nan)
    inside = (k >= lo) & (k < hi)
    out[k[inside] - lo] = values[inside]
    return out


def _fill(u: np.ndarray) -> np.ndarray:
    """Inputs of missing samples (NaN rows), linearly interpolated between the known ones.

    A held elevator switches at some sample; when that sample is lost, the switch happened at it or at the
    next, and either guess is wrong by the whole step half the time. The midpoint is wrong by half the step
    every time, which halves the expected squared error a free run integrates (measured on the c172p with 5 %
    of the records lost: held-out theta fit 80 % holding the last value).
    """
    known = ~np.isnan(u).any(axis=1)
    if known.all():
        return u
    rows = np.arange(len(u))
    return np.column_stack([np.interp(rows, rows[known], u[known, j]) for j in range(u.shape[1])])


def _continuous(A_d: np.ndarray, B_d: np.ndarray, h: float) -> tuple[np.ndarray, ...]:
    """``(A_c, B_c, e^{A_c h}, Gamma(h))`` with ``A_c = logm(A_d)/h``; IdentificationError when there is no real one."""
    n = A_d.shape[0]
    eig = np.linalg.eigvals(A_d)
    bad = eig[(np.abs(eig.imag) <= 1e-9 * np.maximum(1.0, np.abs(eig))) & (eig.real <= 0)]
    if len(bad) or not np.all(np.isfinite(eig)):
        root = float(bad[0].real) if len(bad) else float("nan")
        raise IdentificationError(
            f"no continuous model: the fitted discrete A has the eigenvalue {root:.4g} on the closed negative real "
            f"axis, which has no real logarithm at h = {h:g} s (a mode faster than the sampling, or too little "
            "excitation); sample faster (--h) or fly a richer manoeuvre"
        )
    try:
        model = reconstruct_continuous(A_d, B_d, np.zeros((n, 1)), np.zeros((n, 1)), h)
    except (UserError, np.linalg.LinAlgError, ValueError) as exc:
        raise IdentificationError(f"no continuous model: {exc}") from None
    A_c, B_c = model.A_c, model.B_c
    A_back, gamma = integral_expm(A_c, h)
    if (
        not np.all(np.isfinite(A_c))
        or np.linalg.norm(A_back - A_d) > 1e-8 * max(1.0, float(np.linalg.norm(A_d)))
        or np.linalg.norm(gamma @ B_c - B_d) > 1e-8 * max(1.0, float(np.linalg.norm(B_d)))
    ):
        raise IdentificationError(
            "no continuous model: the matrix logarithm of the fitted discrete A does not "
            "give it back (ill-conditioned fit); fly a richer manoeuvre"
        )
    return A_c, B_c, A_back, gamma


def identify(data: FlightData, holdout: float = HOLDOUT) -> Identification:
    """Identify ``x' = A_c x + B_c u`` from ``data`` (see the module docstring); IdentificationError if it cannot."""
    h = float(data.h)
    names = tuple(data.state_names)
    inputs = tuple(data.input_names)
    k = np.asarray(data.k, dtype=np.int64)
    X = np.asarray(data.states, dtype=float).reshape(len(k), len(names))
    U = np.asarray(data.inputs, dtype=float).reshape(len(k), len(inputs))
    finite = np.isfinite(X).all(axis=1) & np.isfinite(U).all(axis=1)
    k, X, U = k[finite], X[finite], U[finite]
    if len(k) and np.any(np.diff(k) <= 0):
        order = np.unique(k, return_index=True)[1]
        k, X, U = k[order], X[order], U[order]
    n, m = X.shape[1], U.shape[1]
    if len(k) < 2:
        raise IdentificationError(
            f"too short: {len(k)} usable sample(s) in the log; identify needs at least "
            f"{MIN_EXCITATION_S:g} s of excitation"
        )
    t = (k - k[0]) * h
    start, end, lead, tail, spread = _excitation_window(t, U[:, 0], inputs[0])
    seconds = float(t[end - 1] - t[start]) + h
    params = n + m
    needed_pairs = MIN_PAIRS_PER_PARAMETER * params
    if seconds < MIN_EXCITATION_S - 1e-9 or (end - start) * (1 - holdout) < needed_pairs:
        raise IdentificationError(
            f"too short: the excitation lasts {seconds:.1f} s ({end - start} samples at h = {h:g} s); identify needs "
            f"at least {MIN_EXCITATION_S:g} s and {int(math.ceil(needed_pairs / (1 - holdout)))} samples of it "
            f"({holdout:.0%} is held out to validate the model)"
        )
    split = start + int(round((1 - holdout) * (end - start)))
    lead_from = start
    if lead:
        lead_from = int(np.searchsorted(t, t[start - 1] - LEAD_IN_S + 1e-9))
    fit_rows = np.arange(lead_from if lead else start, split)
    notes: list[str] = []

    # pairs (x(k), u(k)) -> x(k+1) of consecutive samples, all inside the fitted span
    nxt = fit_rows[:-1] + 1
    pairs = fit_rows[:-1][k[nxt] == k[fit_rows[:-1]] + 1]
    if len(pairs) < needed_pairs:
        raise IdentificationError(
            f"too short: only {len(pairs)} pairs of consecutive samples in the fitted part "
            f"(the log has gaps); identify needs {needed_pairs}"
        )
    regressor_names = [*names, *inputs]
    if lead:
        quiet = slice(lead_from, start)
        op_x, op_u = X[quiet].mean(axis=0), U[quiet].mean(axis=0)
        source = f"mean of the {t[start - 1] - t[lead_from] + h:.1f} s of trimmed flight before the excitation"
        fitted = _lstsq(np.hstack([X[pairs] - op_x, U[pairs] - op_u]), X[pairs + 1] - op_x, regressor_names)
        A_d, B_d = fitted[:n].T, fitted[n:].T
    else:
        if tail:
            op_u = U[end:].mean(axis=0)
            where = f"the {inputs[0]}'s value after the excitation ({t[-1] - t[end] + h:.1f} s at trim)"
        else:
            op_u = U[start:end].mean(axis=0)
            where = f"the {inputs[0]}'s mean over the excitation (no quiet flight before or after it)"
        centre = X[pairs].mean(axis=0)
        fitted = _lstsq(
            np.hstack([X[pairs] - centre, U[pairs] - op_u, np.ones((len(pairs), 1))]),
            X[pairs + 1] - centre,
            [*regressor_names, "1"],
        )
        A_d, B_d, c = fitted[:n].T, fitted[n : n + m].T, fitted[n + m]
        try:
            op_x = centre + np.linalg.solve(np.eye(n) - A_d, c)
        except np.linalg.LinAlgError:
            raise IdentificationError(
                "no excitation: the fitted model has an integrator (eigenvalue 1): no "
                "equilibrium to take as the operating point; fly a lead-in at trim"
            ) from None
        source = f"equilibrium of the fitted model at {where}"
        notes.append(
            "no trimmed flight before the excitation: the operating point is the fitted model's "
            "equilibrium; a few seconds of trim before the manoeuvre would measure it instead"
        )

    # output error: the free-run fit over the fitted part, from the least-squares model (see the docstring)
    lo_row = lead_from if lead else start
    k0, k1 = int(k[lo_row]), int(k[split - 1]) + 1
    refined = _output_error(A_d, B_d, _grid(k, X - op_x, k0, k1), _fill(_grid(k, U - op_u, k0, k1)), offset=not lead)
    method: dict[str, Any] = {"initial": "equation-error least squares", "refined": False}
    candidates = [(A_d, B_d, np.zeros(n))]
    if refined is not None:
        candidates.insert(0, refined[:3])
        method.update(refined=True, **refined[3])
    else:
        notes.append("the output-error refinement did not improve on least squares: the least-squares model is kept")
    failure: IdentificationError | None = None
    for A_try, B_try, offset in candidates:
        try:
            A_c, B_c, A_back, gamma = _continuous(A_try, B_try, h)
        except IdentificationError as exc:
            failure = failure or exc
            continue
        if failure is not None:
            method["refined"] = False
            notes.append(f"the refined model was refused ({failure}); the least-squares model is kept")
        A_d, B_d, op_x = A_try, B_try, op_x + offset
        break
    else:  # every candidate was refused (there is at least one): failure holds the first refusal
        assert failure is not None
        raise failure
    if np.max(np.abs(np.angle(np.linalg.eigvals(A_d)))) > 0.5 * math.pi:
        notes.append(
            f"a mode rotates more than a quarter turn per sample (h = {h:g} s): its frequency is near "
            "Nyquist and poorly resolved"
        )
    # the model as the plant file has it (x' = A_c x + B_c u, exactly discretised): what the validation runs
    A_v, B_v = A_back, gamma @ B_c

    def run(lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Free run over rows lo..hi-1 from the measured state at lo; (t, y, y_hat) at the samples present."""
        k0, k1 = int(k[lo]), int(k[hi - 1]) + 1
        y = _grid(k, X - op_x, k0, k1)
        u = _fill(_grid(k, U - op_u, k0, k1))
        y_hat = simulate(A_v, B_v, y[0], u)
        present = ~np.isnan(y).any(axis=1)
        return (np.arange(k0, k1)[present] - k[0]) * h, y[present], y_hat[present]

    disturbance = gust_from_residual(k, X - op_x, U - op_u, A_v, B_v, names, h)
    tv, yv, yv_hat = run(split, end)
    _te, ye, ye_hat = run(start, split)
    fit_v = nrmse_fit(yv, yv_hat)
    fit_e = nrmse_fit(ye, ye_hat)
    if not np.all(np.isfinite(yv_hat)):
        notes.append("the model diverges in the free run over the held-out data")
    op = {name: float(v) for name, v in zip(names, op_x, strict=True)}
    op.update({name: float(v) for name, v in zip(inputs, op_u, strict=True)})
    return Identification(
        h=h,
        state_names=names,
        input_names=inputs,
        operating_point=op,
        operating_point_source=source,
        A_d=A_d,
        B_d=B_d,
        A_c=A_c,
        B_c=B_c,
        fit_validation={name: float(f) for name, f in zip(names, fit_v, strict=True)},
        fit_estimation={name: float(f) for name, f in zip(names, fit_e, strict=True)},
        modes=modes_of(A_c),
        samples=len(k),
        samples_estimation=len(pairs),
        samples_validation=len(yv),
        excitation={
            "start_s": float(t[start]),
            "end_s": float(t[end - 1] + h),
            "seconds": seconds,
            "spread_deg": spread,
            "lead_in_s": float(t[start] - t[0]) if lead else 0.0,
            "tail_s": float(t[-1] - t[end] + h) if tail else 0.0,
        },
        validation_span_s=(float(tv[0]) if len(tv) else 0.0, float(tv[-1]) if len(tv) else 0.0),
        validation_run={"t": tv, "y": yv, "y_hat": yv_hat},
        method=method,
        notes=notes,
        disturbance=disturbance,
    )


def gust_from_residual(
    k: np.ndarray, x: np.ndarray, u: np.ndarray, A_d: np.ndarray, B_d: np.ndarray, names: tuple[str, ...], h: float
) -> dict[str, float] | None:
    """The gust input the flight met, from the model's one-step residual: ``{"sigma", "time_constant", "samples"}``.

    What the model does not explain from one sample to the next, ``r(k) = x(k+1) - A x(k) - B u(k)``, is projected
    on the plant's gust direction ``Dd`` (the discretised ``D_cd``, the alpha column of ``A_c``: a vertical gust seen
    as an angle of attack) by least squares, and the sequence fitted with a first-order Gauss-Markov process: its
    standard deviation, and its integral time scale ``h (1/2 + sum rho(j))`` over the lags before the
    autocorrelation ``rho`` first crosses zero, as the time constant. Why not the lag-one fit ``rho(1) = e^{-h/T}``:
    it sees only the fast part; on a c172p in light turbulence it gave 0.15 s where the integral scale is 0.43 s,
    and a low-passed estimate then came out 1.5x the prediction made from it. In calm air it measures the model's
    own error (small); in turbulence, the air. None without alpha or with too few pairs.
    """
    if "alpha" not in names:
        return None
    pairs = np.flatnonzero(np.diff(k) == 1)
    if len(pairs) < 20:
        return None
    Dd = (A_d - np.eye(len(names)))[:, [names.index("alpha")]]  # Gamma(h) A_c e_alpha = (e^{A_c h} - I) e_alpha
    residual = x[pairs + 1] - x[pairs] @ A_d.T - u[pairs] @ B_d.T
    d = np.linalg.lstsq(Dd, residual.T, rcond=None)[0][0]
    d = d - d.mean()
    sigma = float(np.std(d))
    return {"sigma": sigma, "time_constant": _integral_time_scale(d, h) if sigma > 0 else h, "samples": int(len(pairs))}


def _integral_time_scale(d: np.ndarray, h: float, max_lag_s: float = 20.0) -> float:
    """``h (1/2 + sum_{j >= 1} rho(j))`` up to the first lag where the autocorrelation ``rho`` is no longer positive
    (at least half a sample: a white sequence)."""
    d = d - d.mean()
    energy = float(d @ d)
    total = 0.5
    for lag in range(1, min(len(d) // 2, int(max_lag_s / h))):
        rho = float(d[:-lag] @ d[lag:]) / energy
        if rho <= 0.0:
            break
        total += rho
    return float(total * h)
