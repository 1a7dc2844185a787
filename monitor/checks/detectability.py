"""What fault can be seen: the smallest elevator bias an alarm detects within T seconds, at a false-alarm budget.

With a bias ``b`` from sample ``k0`` on, the loop is linear, so ``f_hat(k) = b s(k) + n(k)``: ``s`` is the unit-step
response of ``f_hat`` (``s(k0) = 0``, ``s -> 1``; from ``monitor.model.closed_loop``) and ``n`` is what the
disturbance alone makes of ``f_hat``. The alarm (``monitor.service.alarm``) raises once ``|f_hat| >= c`` for
``S`` samples in a row (``--alarm-samples``, 2 by default). Detected within ``T`` means raised by sample
``k0 + floor(T/h)``. Two models of ``n``:

* **bounded** (``--disturbance-bound D``): ``|n(k)| <= c0`` for every delay sequence, proven
  (``monitor.checks.threshold``). The alarm is ``c = 1.25 c0`` (what ``run --alarm-threshold auto`` uses):
  no false alarm, ever. A window of ``S`` samples ending at ``k`` surely raises it when ``b s(j) - c0 >= c`` for
  each ``j`` in it, so ``b_min = (c + c0) / max_k min_{j in window(k)} s(j)``, ``k <= k0 + T/h``.
* **turbulence** (Gaussian): ``d`` is the plant's ``[disturbance]`` Gauss-Markov process, its sigma scaled from
  the level it was measured in to the level asked by the ratio of JSBSim's MIL-F-8785C vertical gust
  intensities at the altitude (:func:`gust_sigma_ft_s`; the scale length, hence the time constant, depends on
  the altitude only). The loop augmented with the shaping filter gives the stationary variance ``v0`` of
  ``f_hat`` and its lag-one correlation ``rho`` (discrete Lyapunov equation); Rice's formula with the spectral
  moments ``lambda0 = v0``, ``lambda2 = 2 v0 (1 - rho) / h^2`` gives the rate of upcrossings of ``c``,
  ``nu(c) = sqrt(lambda2 / lambda0) / (2 pi) exp(-c^2 / (2 v0))``, and the threshold solves
  ``2 nu(c) 3600 = N`` (both signs of ``f_hat``). Every raise of the alarm needs a crossing of ``+-c``, so the
  alarms per hour are at most that (persistence and the clear hysteresis only remove some; and Rice's rate is
  above the sampled sequence's own, by 16 % at ``c = 4.3 sigma``, ``rho = 0.88``). Detected within T with
  probability ``P`` (0.95): the linear loop in 4000 seeded draws of that air (stationary at onset), per draw the
  smallest ``b`` for which a window of ``S`` samples after onset is all ``>= c``; ``b_min`` is their P-quantile.

The alarm watches the *reported* estimate: with a ``fault_time_constant`` in the gains file it is low-passed
(``monitor.model.estimator``), and the step response and the noise are taken through that filter too (the proven
bound holds for it as well: the filter averages with positive weights summing to one).

Delays: the step response and the Gaussian figures are at constant delays (worst over a grid of the
interval: smallest ``s``, largest ``sigma`` and ``c``); only ``c0`` covers every time-varying sequence.

The prediction is linear algebra only. Its check against the real thing, ``detectability --monte-carlo``,
flies JSBSim in process and lives apart, in ``monitor.jsbsim_flights`` (``monte_carlo``): the monitor's
``Estimator`` answering each sample at once with the sample mapped by the plant's signal map as the live
service does, the delay drawn uniformly over the plant's interval, seeded flights.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.signal

from monitor.errors import UserError
from monitor.model.closed_loop import Gains, LoopMatrices, closed_loop, steady_state
from monitor.model.delay_model import b0_of_tau, tau_grid
from monitor.model.estimator import report_pole
from monitor.model.plant import Plant
from monitor.wire import TURBULENCE_INTENSITY

__all__ = [
    "gust_sigma_ft_s",
    "scaled_disturbance",
    "NoiseFigures",
    "fhat_noise",
    "upcrossing_rate",
    "gaussian_threshold",
    "turbulence_threshold",
    "gaussian_bias",
    "step_response",
    "detectable_bias",
    "Detectability",
    "detectability",
    "FALSE_ALARMS_PER_HOUR",
    "WITHIN_S",
    "PROBABILITY",
]

# the defaults live in the light package module, so that the command's help text does not import this one
from monitor.checks import FALSE_ALARMS_PER_HOUR, PROBABILITY, WITHIN_S  # noqa: E402

GRID = 5  # constant delays over the interval for the worst case

# JSBSim's MIL-F-8785C vertical gust intensity sigma_w (ft/s), FGWinds: above 2000 ft AGL the probability-of-
# exceedance table (rows: JSBSim's severity index, columns: altitude in ft), below 1000 ft 0.1 W20, linear in
# between. Checked against JSBSim 1.3.3 flights of the c172p at 100 kt, seed 1 (std of turb-down-fps, same
# random stream): moderate/light 1.415 (table 1.418) at 3000 ft and 1.489 (1.497) at 7000 ft, severe/light
# 2.89 (2.91) over the first minute at 3000 ft (later the aircraft lost altitude).
_POE_ALTITUDES_FT = (
    500.0,
    1750.0,
    3750.0,
    7500.0,
    15000.0,
    25000.0,
    35000.0,
    45000.0,
    55000.0,
    65000.0,
    75000.0,
    80000.0,
)
_POE_TABLE = {
    3: (6.6, 6.9, 7.4, 6.7, 4.6, 2.7, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0),
    4: (8.6, 9.6, 10.6, 10.1, 8.0, 6.6, 5.0, 4.2, 2.7, 0.0, 0.0, 0.0),
    6: (15.6, 17.6, 23.0, 23.6, 22.1, 20.0, 16.0, 15.1, 12.1, 7.9, 6.2, 5.1),
}


def gust_sigma_ft_s(level: str, altitude_ft: float) -> float:
    """sigma_w of JSBSim's turbulence ``level`` (sim_vehicle's --turbulence) at ``altitude_ft`` above ground."""
    if level not in TURBULENCE_INTENSITY:
        raise UserError(f"turbulence level '{level}': expected one of {', '.join(TURBULENCE_INTENSITY)}")
    setting = TURBULENCE_INTENSITY[level]
    if setting is None:
        return 0.0
    w20, severity = setting
    h = max(float(altitude_ft), 10.0)
    table = float(np.interp(h, _POE_ALTITUDES_FT, _POE_TABLE[severity]))
    if h <= 1000.0:
        return 0.1 * w20
    if h <= 2000.0:
        return 0.1 * w20 + (h - 1000.0) / 1000.0 * (table - 0.1 * w20)
    return table


def scaled_disturbance(plant: Plant, level: str, altitude_ft: float) -> tuple[float, float, float]:
    """``(sigma, time_constant, ratio)`` of the plant's ``[disturbance]`` at turbulence ``level``; one-line errors."""
    dist = plant.disturbance
    if dist is None:
        raise UserError(
            f"plant {plant.name} has no [disturbance] table: identify it from a flight in turbulence, or "
            "give --disturbance-bound"
        )
    if dist.turbulence is None:
        raise UserError(
            f"plant {plant.name}: its [disturbance] table does not say which turbulence it was measured "
            "in (key turbulence), so it cannot be scaled to another level"
        )
    if level == "none":
        raise UserError(
            "--turbulence none: no turbulence, nothing to set a threshold against; pick a level or give "
            "--disturbance-bound"
        )
    measured = gust_sigma_ft_s(dist.turbulence, altitude_ft)
    if measured <= 0:
        raise UserError(
            f"plant {plant.name}: its [disturbance] was measured in turbulence '{dist.turbulence}', "
            "which has no intensity to scale from"
        )
    ratio = gust_sigma_ft_s(level, altitude_ft) / measured
    return dist.sigma * ratio, dist.time_constant, ratio


# --- the Gaussian noise on f_hat ----------------------------------------------------------------------------


@dataclass
class NoiseFigures:
    """Stationary ``f_hat`` with no fault under a Gauss-Markov ``d``, at the worst constant delay."""

    std: float  # sqrt(lambda0)
    rho: float  # lag-one correlation
    tau: float  # the constant delay where they are taken (the one with the highest threshold)


def _loops(plant: Plant, gains: Gains, points: int = GRID) -> list[tuple[float, LoopMatrices]]:
    steady = steady_state(plant, gains)
    return [
        (float(t), closed_loop(plant, gains, b0_of_tau(plant, float(t)), steady=steady))
        for t in tau_grid(plant, points)
    ]


def _noise_at(
    loop: LoopMatrices, p: int, sigma: float, time_constant: float, h: float, keep: float = 0.0
) -> tuple[float, float]:
    """``(v0, v1)``: variance and lag-one covariance of the reported f_hat with the shaping filter in the loop."""
    A, B, C = _augmented(loop, p, sigma, time_constant, h, keep)
    P = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
    v0 = np.diag(C @ P @ C.T)
    v1 = np.diag(C @ A @ P @ C.T)
    i = int(np.argmax(v0))  # the fault channel with the largest variance
    return float(v0[i]), float(v1[i])


def upcrossing_rate(level: float, std: float, rho: float, h: float) -> float:
    """Rice: upcrossings of ``level`` per second by a stationary Gaussian sequence (std, lag-one correlation,
    step h)."""
    if std <= 0:
        return 0.0
    return math.sqrt(2.0 * max(1.0 - rho, 0.0)) / (2.0 * math.pi * h) * math.exp(-0.5 * (level / std) ** 2)


def gaussian_threshold(std: float, rho: float, h: float, per_hour: float) -> float:
    """The ``c`` with ``2 nu(c) 3600 = per_hour`` (0 when even ``c = 0`` is crossed less often)."""
    base = 2.0 * 3600.0 * upcrossing_rate(0.0, std, rho, h)
    return std * math.sqrt(2.0 * math.log(base / per_hour)) if base > per_hour else 0.0


def fhat_noise(
    plant: Plant,
    gains: Gains,
    sigma: float,
    time_constant: float,
    per_hour: float,
    report_time_constant: float | None = None,
    points: int = GRID,
) -> tuple[NoiseFigures, float]:
    """``(noise, threshold)`` at the constant delay of the grid with the highest threshold; one-line errors."""
    if not (sigma > 0 and time_constant > 0):
        raise UserError(f"the disturbance needs sigma > 0 and time_constant > 0, got {sigma:g} and {time_constant:g}")
    if not (per_hour > 0 and math.isfinite(per_hour)):
        raise UserError(f"--false-alarms-per-hour must be a positive number, got {per_hour:g}")
    best: tuple[NoiseFigures, float] | None = None
    for tau, loop in _loops(plant, gains, points):
        keep = report_pole(plant.h, report_time_constant)
        v0, v1 = _noise_at(loop, plant.p, sigma, time_constant, plant.h, keep)
        std, rho = math.sqrt(v0), v1 / v0 if v0 > 0 else 0.0
        c = gaussian_threshold(std, rho, plant.h, per_hour)
        if best is None or c > best[1]:
            best = (NoiseFigures(std=std, rho=rho, tau=tau), c)
    assert best is not None  # the delay grid has at least one point
    noise, c = best
    if not c > 0:
        raise UserError(
            f"{per_hour:g} false alarms per hour is more than |f_hat| crosses even 0 "
            f"({2 * 3600 * upcrossing_rate(0.0, noise.std, noise.rho, plant.h):.3g} per hour): ask for fewer"
        )
    return best


def turbulence_threshold(
    plant: Plant,
    gains: Gains,
    level: str,
    altitude_ft: float = 3000.0,
    per_hour: float = FALSE_ALARMS_PER_HOUR,
    report_time_constant: float | None = None,
) -> float:
    """The Gaussian alarm threshold alone (``run --alarm-threshold auto --turbulence LEVEL``)."""
    sigma, time_constant, _ = scaled_disturbance(plant, level, altitude_ft)
    return fhat_noise(plant, gains, sigma, time_constant, per_hour, report_time_constant)[1]


# --- the fault's step response and the smallest bias ---------------------------------------------------------


def _step(loop: LoopMatrices, p: int, samples: int, keep: float = 0.0) -> np.ndarray:
    """``s(j)``, j = 0..samples, of one loop: the reported f_hat after a unit bias from sample 0 (``1 - e_f``,
    low-passed as reported when ``keep`` > 0)."""
    x = loop.B[:, p:][:, 0].copy()  # the unit step's Delta f at sample -1
    s = np.empty(samples + 1)
    for j in range(samples + 1):
        s[j] = 1.0 - float(loop.C_ef[0] @ x)
        x = loop.A @ x
    reported: np.ndarray = scipy.signal.lfilter([1.0 - keep], [1.0, -keep], s)
    return reported


def step_response(
    plant: Plant, gains: Gains, samples: int, report_time_constant: float | None = None, points: int = GRID
) -> np.ndarray:
    """``s(j)``, j = 0..samples: f_hat after a unit bias from sample 0, the smallest over constant delays."""
    keep = report_pole(plant.h, report_time_constant)
    worst: np.ndarray = np.min(
        [_step(loop, plant.p, samples, keep) for _, loop in _loops(plant, gains, points)], axis=0
    )
    return worst


def _augmented(
    loop: LoopMatrices, p: int, sigma: float, time_constant: float, h: float, keep: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C)`` of the loop driven by the Gauss-Markov ``d`` through its shaping filter, with the reported
    estimate's low-pass ``f_rep(k) = keep f_rep(k-1) + (1 - keep) f_hat(k)`` last; C gives ``f_rep`` (no fault:
    ``f_hat = -e_f``). State ``[xi; d; f_rep(k-1)]``."""
    N, q = loop.A.shape[0], loop.C_ef.shape[0]
    a = math.exp(-h / time_constant)
    C = np.hstack([-(1.0 - keep) * loop.C_ef, np.zeros((q, p)), keep * np.eye(q)])
    A = np.block([[loop.A, loop.B[:, :p], np.zeros((N, q))], [np.zeros((p, N)), a * np.eye(p), np.zeros((p, q))], [C]])
    B = np.zeros((N + p + q, p))
    B[N : N + p] = math.sqrt(1.0 - a * a) * sigma * np.eye(p)
    if np.max(np.abs(np.linalg.eigvals(A))) >= 1.0:
        raise UserError("the loop is unstable at a constant delay in the interval (see fault-monitor verify)")
    return A, B, C


def gaussian_bias(
    plant: Plant,
    gains: Gains,
    sigma: float,
    time_constant: float,
    threshold: float,
    samples: int,
    alarm_samples: int,
    probability: float,
    report_time_constant: float | None = None,
    realizations: int = 4000,
    seed: int = 0,
    points: int = GRID,
) -> tuple[float, float]:
    """``(b, t)``: the bias the alarm detects within ``samples`` of onset with ``probability``, and the median
    detection time (s) at that bias, for the linear loop in the Gauss-Markov air, worst constant delay.

    ``f_hat = b s + n`` with ``n`` drawn from the model (stationary at onset, seeded): per realization the smallest
    ``b`` for which some window of ``alarm_samples`` samples after onset is all ``>= threshold`` is
    ``min over windows of max over its samples of (threshold - n) / s``; ``b`` is their ``probability`` quantile.
    """
    rng = np.random.default_rng(seed)
    keep = report_pole(plant.h, report_time_constant)
    best = (0.0, 0.0)
    for _, loop in _loops(plant, gains, points):
        A, B, C = _augmented(loop, plant.p, sigma, time_constant, plant.h, keep)
        P = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
        w, V = np.linalg.eigh(0.5 * (P + P.T))
        x = (V * np.sqrt(np.clip(w, 0.0, None))) @ rng.standard_normal((len(w), realizations))
        n = np.empty((samples + 1, realizations))
        for j in range(samples + 1):
            n[j] = C[0] @ x
            x = A @ x + B @ rng.standard_normal((B.shape[1], realizations))
        s = _step(loop, plant.p, samples, keep)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            need = np.where(s > 0, (threshold - n) / s, np.where(n >= threshold, 0.0, np.inf))
        need = np.maximum(need, 0.0)
        windows = np.lib.stride_tricks.sliding_window_view(need, alarm_samples, axis=0).max(axis=-1)
        b = float(np.quantile(windows.min(axis=0), probability))
        if b > best[0]:
            first = np.argmax(windows <= b, axis=0) + alarm_samples - 1  # window index -> its last sample
            hit = (windows <= b).any(axis=0)
            best = (b, float(np.median(first[hit])) * plant.h if hit.any() else math.nan)
    return best


def detectable_bias(s: np.ndarray, needed: float, alarm_samples: int) -> tuple[float, int]:
    """``(b, j)``: the smallest ``b`` with ``b s(i) >= needed`` over a window of ``alarm_samples`` ending at some
    ``j`` of ``s``, and that ``j``; ``(inf, -1)`` when ``s`` never stays positive that long."""
    S = int(alarm_samples)
    if len(s) < S:
        return math.inf, -1
    windows = np.lib.stride_tricks.sliding_window_view(s, S).min(axis=1)  # windows[i] ends at sample i + S - 1
    best = float(windows.max())
    if best <= 0:
        return math.inf, -1
    i = int(np.argmax(windows >= (1.0 - 1e-3) * best))  # the earliest window within 0.1 % of the best, reported
    return needed / best, i + S - 1


@dataclass
class Detectability:
    """What ``fault-monitor detectability`` computes (plant units)."""

    mode: str  # "bounded" (proven) or "turbulence" (Gaussian)
    threshold: float  # the alarm level c that achieves b_min
    clear: float
    alarm_samples: int
    within_s: float
    bias: float  # b_min: the smallest bias detected within within_s (surely, or with `probability`)
    detected_at_s: float  # the end of the window that detects it, seconds after onset
    step_at: float  # s(j) there (the slowest constant delay)
    false_alarms_per_hour: float  # 0 for the proven bound; the budget otherwise
    probability: float | None = None
    disturbance_bound: float | None = None
    noise_bound: float | None = None  # c0: proven sup |f_hat| with no fault
    noise_bound_method: str | None = None
    turbulence: str | None = None
    altitude_ft: float | None = None
    sigma_d: float | None = None  # the disturbance's std at that level
    time_constant: float | None = None
    sigma_ratio: float | None = None  # sigma_w(level) / sigma_w(measured level)
    fhat_std: float | None = None
    fhat_rho: float | None = None
    tau_worst: float | None = None
    step_response: list[float] = field(default_factory=list)  # s(j), j = 0..floor(T/h)
    report_time_constant: float | None = None  # the low-pass on the reported f_hat (s), None: none
    delays: str = "step response: worst constant delay of the interval"

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def detectability(
    plant: Plant,
    gains: Gains,
    *,
    disturbance_bound: float | None = None,
    turbulence: str | None = None,
    altitude_ft: float = 3000.0,
    false_alarms_per_hour: float = FALSE_ALARMS_PER_HOUR,
    within_s: float = WITHIN_S,
    alarm_samples: int = 2,
    probability: float = PROBABILITY,
    report_time_constant: float | None = None,
) -> Detectability:
    """The figures described in the module docstring; exactly one of ``disturbance_bound`` and ``turbulence``.

    ``report_time_constant``: the low-pass of the reported estimate the alarm watches (the gains'
    fault_time_constant)."""
    if (disturbance_bound is None) == (turbulence is None):
        raise UserError("give exactly one of --turbulence LEVEL and --disturbance-bound D")
    if not (within_s > 0 and math.isfinite(within_s)):
        raise UserError(f"--within must be a positive number of seconds, got {within_s:g}")
    if alarm_samples < 1:
        raise UserError(f"--alarm-samples must be at least 1, got {alarm_samples}")
    if not 0.5 < probability < 1.0:
        raise UserError(f"--probability must be in (0.5, 1), got {probability:g}")
    gains.check_shapes(plant)
    try:
        steady_state(plant, gains)
    except ValueError:
        raise UserError("the loop has a pole at 1 (a constant fault has no steady state)") from None
    samples = int(math.floor(within_s / plant.h + 1e-9))
    s = step_response(plant, gains, samples, report_time_constant)
    common = dict(
        alarm_samples=alarm_samples,
        within_s=within_s,
        step_response=s.tolist(),
        report_time_constant=report_time_constant,
    )
    if disturbance_bound is not None:
        from monitor.checks import AUTO_MARGIN
        from monitor.checks.threshold import fault_threshold

        bound = fault_threshold(plant, gains, disturbance_bound)
        c0 = bound.threshold
        c = AUTO_MARGIN * c0
        if not c > 0:
            raise UserError("the proven bound is 0 (no disturbance reaches f_hat): any threshold works")
        b, j = detectable_bias(s, c + c0, alarm_samples)
        return Detectability(
            mode="bounded",
            threshold=c,
            clear=0.5 * c,
            bias=b,
            detected_at_s=j * plant.h,
            step_at=float(s[j]) if j >= 0 else math.nan,
            false_alarms_per_hour=0.0,
            disturbance_bound=float(disturbance_bound),
            noise_bound=c0,
            noise_bound_method=bound.method,
            **common,
        )
    assert turbulence is not None  # exactly one of the two (checked above)
    sigma, time_constant, ratio = scaled_disturbance(plant, turbulence, altitude_ft)
    noise, c = fhat_noise(plant, gains, sigma, time_constant, false_alarms_per_hour, report_time_constant)
    b, t = gaussian_bias(
        plant, gains, sigma, time_constant, c, samples, alarm_samples, probability, report_time_constant
    )
    j = min(int(round(t / plant.h)), samples) if math.isfinite(t) else -1
    return Detectability(
        mode="turbulence",
        threshold=c,
        clear=0.5 * c,
        bias=b,
        detected_at_s=t,
        step_at=float(s[j]) if j >= 0 else math.nan,
        false_alarms_per_hour=false_alarms_per_hour,
        probability=probability,
        turbulence=turbulence,
        altitude_ft=altitude_ft,
        sigma_d=sigma,
        time_constant=time_constant,
        sigma_ratio=ratio,
        fhat_std=noise.std,
        fhat_rho=noise.rho,
        tau_worst=noise.tau,
        **common,
    )
