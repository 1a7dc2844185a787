"""Observer (5) and controller (6) for one vehicle, one sample at a time: the maths of the live loop.

Pure and small on purpose: ``monitor run``, ``monitor analyse``, the demo's Monte-Carlo and the tests
step the same code, and ``verify`` checks the same matrices in closed form. Per sample k, with
measurement ``y(k)`` and u(k-1) the deflection in force at the instant:

    r(k)    = y(k) - C x_hat(k)                                   (residual)
    u(k)    = sat(K1 y(k) + K2 u(k-1) + K3 f_hat(k))              (controller, eq. 6, at the actuator limit)
    x_hat(k+1) = A x_hat + B0 u(k) + B1 u(k-1) + Df f_hat + L r   (observer, eq. 5)
    f_hat(k+1) = f_hat + M r

With an operating point (a plant identified about a trim, monitor/link/signals.py) every quantity here is a
deviation from it (y - y0, u - u0); only the saturation knows u0: the limit holds for u0 + u.

``f_hat(k)`` (the estimate that went into ``u(k)``) is what is reported for sample k, so that
``e_f(k) = f(k) - f_hat(k)`` lines up with the truth at the same k. With a ``fault_time_constant`` T (the gains
file's, ``fault-monitor design --fault-time-constant``), the *reported* estimate is that one low-passed,
``f_rep(k) = a f_rep(k-1) + (1 - a) f_hat(k)``, ``a = e^{-h/T}``: the channel a user watches and alarms on gets
a chosen bandwidth, while the loop (controller and observer) keeps the raw estimate, so its certificate is
unchanged. Why: in turbulence the deadbeat estimate passes every gust that looks like a fault; on a c172p in
light turbulence, 1 s of filtering took the false alarms at 1 deg in 120 s from 34 to 0, for a detection 0.5 s
later (docs/explanation/turbulence.md, the trade table).

Which u(k-1): the contract says the deflection the vehicle *reports* at sample k (``u_prev``), because a
command that was lost or late never acted; only when no report came does the estimator use its own
last command. Observe-only (``observe``): the vehicle's own controller issued u(k), reported with the
sample, and only eq. (5) runs. Compensation (``compensate``): the same, and a fault term alone, ``G f_hat(k)``,
goes back for the vehicle to add to its own controller's deflection. Past one sample (a
lagged plant, ``monitor.model.long_delay``) the report at k is whichever command is in force, not u(k-1); the
lagged model carries the commands in flight itself, so the estimator keeps its own last command and ignores
the report (the certificate covers every arrival pattern).
Known inputs (a plant's ``[known_inputs]``, ``monitor.model.known_inputs``): ``step``, ``observe`` and
``compensate`` take ``known``, the continuous-time term vector at sample k (state units); with it, and a plant
that has known inputs, the prediction gets ``Gamma known`` added, ``Gamma = int_0^h e^{A_c s} ds``:
``x_hat(k+1) = ... + Gamma known(k)``. The certificates are unchanged: the known input drives the plant and the
observer alike and cancels in the estimation error. A lost sample is predicted without it.
Why saturate here: a command beyond the actuator's travel is not what acts on the plant, and an observer fed
the unsaturated value would learn a fault that is not there.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from operator import mul
from typing import TYPE_CHECKING

import numpy as np

from monitor.model.closed_loop import Gains, fault_compensation
from monitor.model.plant import Plant

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["EstimatorState", "StepResult", "Estimator", "report_pole"]


_GAP_IN_FLOATS = 8  # lost samples predicted one by one over floats; a longer gap takes one matrix power


def _floats(values: ArrayLike) -> list[float]:
    """A vector as a list of floats: a list as it is (the live loop's), anything else through numpy."""
    if isinstance(values, list):
        try:
            return [float(e) for e in values]
        except TypeError:  # nested: a column written as a list of lists
            pass
    return [float(e) for e in np.ravel(values)]


def report_pole(h: float, fault_time_constant: float | None) -> float:
    """The reported estimate's low-pass pole ``a = e^{-h/T}`` (module docstring); 0 without a time constant."""
    return math.exp(-h / fault_time_constant) if fault_time_constant else 0.0


class EstimatorState:
    """Everything one vehicle's loop remembers between samples: ``z = [x_hat; f_hat; u(k-1)]``.

    Why a list inside: the estimator's products run over plain floats, and a numpy array made and taken apart
    again every sample cost more than the products. ``z`` still hands out (and takes) a numpy array, made on
    demand; once handed out, the array is what the next step reads, so a caller may change it in place.
    """

    __slots__ = ("n", "q", "k_last", "f_reported", "_values", "_array")

    def __init__(
        self,
        z: np.ndarray | list[float],
        n: int,
        q: int,
        k_last: int | None = None,
        f_reported: list[float] | None = None,  # the low-passed estimate (fault_time_constant), None: none yet
    ) -> None:
        self.n, self.q, self.k_last, self.f_reported = n, q, k_last, f_reported
        self._values: list[float] = z if isinstance(z, list) else []
        self._array: np.ndarray | None = None if isinstance(z, list) else z

    @property
    def z(self) -> np.ndarray:
        if self._array is None:
            self._array = np.array(self._values)
        return self._array

    @z.setter
    def z(self, value: np.ndarray) -> None:
        self._array = value

    def values(self) -> list[float]:
        """``z`` as a fresh list of floats (the estimator's working copy)."""
        return self._array.tolist() if self._array is not None else self._values.copy()

    def set_values(self, z: list[float]) -> None:
        """The new ``z`` (a list the state now owns)."""
        self._values, self._array = z, None

    @property
    def x_hat(self) -> np.ndarray:
        return self.z[: self.n]

    @property
    def f_hat(self) -> np.ndarray:
        return self.z[self.n : self.n + self.q]

    @property
    def u_prev(self) -> np.ndarray:
        return self.z[self.n + self.q :]

    def __repr__(self) -> str:
        return f"EstimatorState(z={self.z!r}, n={self.n}, q={self.q}, k_last={self.k_last})"


class StepResult:
    """One step's outcome. Kept as lists of floats (what the live loop formats and sends); the numpy arrays
    ``u``, ``x_hat``, ``f_hat`` and ``residual`` are made on first use (tests, analyses)."""

    __slots__ = ("k", "skipped", "reset", "u_values", "x_hat_values", "f_hat_values", "residual_values", "_arrays")

    def __init__(
        self,
        k: int,
        u: list[float],  # the command (saturated) or, observe-only, the reported u(k)
        x_hat: list[float],  # estimate at k (before the update)
        f_hat: list[float],  # estimate at k (before the update), as reported (low-passed with a fault_time_constant)
        residual: list[float],
        skipped: int,  # samples predicted open-loop because their telemetry never arrived
        reset: bool = False,  # the state had become non-finite and was reset to zero
    ) -> None:
        self.k, self.skipped, self.reset = k, skipped, reset
        self.u_values, self.x_hat_values, self.f_hat_values, self.residual_values = u, x_hat, f_hat, residual
        self._arrays: dict[str, np.ndarray] = {}

    def _array(self, name: str, values: list[float]) -> np.ndarray:
        out = self._arrays.get(name)
        if out is None:
            out = self._arrays[name] = np.array(values, dtype=float)
        return out

    @property
    def u(self) -> np.ndarray:
        return self._array("u", self.u_values)

    @property
    def x_hat(self) -> np.ndarray:
        return self._array("x_hat", self.x_hat_values)

    @property
    def f_hat(self) -> np.ndarray:
        return self._array("f_hat", self.f_hat_values)

    @property
    def residual(self) -> np.ndarray:
        return self._array("residual", self.residual_values)

    def __repr__(self) -> str:
        return (
            f"StepResult(k={self.k}, u={self.u_values}, x_hat={self.x_hat_values}, f_hat={self.f_hat_values}, "
            f"residual={self.residual_values}, skipped={self.skipped}, reset={self.reset})"
        )


class Estimator:
    """The FE/FTC law for one plant and one set of gains; state lives in ``EstimatorState``.

    Why precomputed matrices: the live loop runs this per sample per vehicle. ``_U`` gives
    ``u = _U [z; y]`` and ``_O`` gives ``[x_hat+; f_hat+; r] = _O [x_hat; f_hat; u(k-1); y; u(k)]``; the
    equations in the module docstring are what they are built from and what the tests check. Why the
    products in plain Python over rows of floats: at these sizes (a handful of states) numpy's per-call
    overhead is most of the cost; plain floats take a third of the time (benchmarks/bench_monitor.py).
    """

    def __init__(
        self,
        plant: Plant,
        gains: Gains,
        max_gap: int = 50,
        u_limit: float | None = None,
        u0: ArrayLike | None = None,
        fault_time_constant: float | None = None,
    ) -> None:
        """``u0``: the operating point of the inputs when the plant works in deviations (``u`` here is
        ``u_abs - u0``): the actuator limit holds for the absolute deflection, so ``u`` is saturated to
        ``[-limit - u0, limit - u0]``. None: zero. ``fault_time_constant``: seconds of the low-pass on the
        reported estimate (module docstring); None: reported as estimated."""
        self._keep = report_pole(plant.h, fault_time_constant)
        gains.check_shapes(plant)
        self.plant = plant
        self.gains = gains
        self.max_gap = max_gap
        self.u_limit = u_limit if u_limit is not None else plant.actuator.limit
        self.u0 = [float(v) for v in np.ravel(u0)] if u0 is not None else [0.0] * plant.m
        A, B0, B1, C, Df = plant.A, plant.B0, plant.B1, plant.C, plant.Df
        n, q, m, l = plant.n, plant.q, plant.m, plant.l
        self._U = np.hstack([np.zeros((m, n)), gains.K3, gains.K2, gains.K1])
        self._O = np.vstack(
            [
                np.hstack([A - gains.L @ C, Df, B1, gains.L, B0]),
                np.hstack([-gains.M @ C, np.eye(q), np.zeros((q, m)), gains.M, np.zeros((q, m))]),
                np.hstack([-C, np.zeros((l, q)), np.zeros((l, m)), np.eye(l), np.zeros((l, m))]),
            ]
        )
        N = n + q + m
        predict = np.eye(N)  # a lost sample: no innovation, the actuator held u(k-1)
        predict[:n, :n] = A
        predict[:n, n : n + q] = Df
        predict[:n, n + q :] = B0 + B1
        self._predict_T = predict
        self._predict_rows = predict.tolist()
        self._A_rows, self._B0_rows, self._B01_rows = A.tolist(), B0.tolist(), (B0 + B1).tolist()
        self._lags = plant.lags
        self._m, self._N, self._nq = m, N, n + q
        self._n_reported = plant.physical.n  # x_hat as reported: the aircraft's state, not the commands in flight
        self._U_rows = self._U.tolist()
        self._compensation_rows = fault_compensation(plant).tolist()
        self._skipped = 0
        # observe-only after lost samples: the state read from the outputs, when they give it (C square and
        # well conditioned, as an identified model's C = I; not a lagged plant, whose commands in flight are state)
        self._reseed: list[list[float]] | None = None
        if plant.lags is None and C.shape[0] == C.shape[1] and np.linalg.cond(C) < 1e8:
            self._reseed = np.linalg.inv(C).tolist()
        ki = plant.known_inputs
        self._gamma_rows: list[list[float]] | None = ki.gamma.tolist() if ki is not None else None
        self._O_rows = self._O.tolist()
        self._lim = float(self.u_limit) if self.u_limit is not None else None
        # per input: the saturation bounds in deviation coordinates
        self._bounds = [(-self._lim - c, self._lim - c) for c in self.u0] if self._lim is not None else None

    def initial_state(self) -> EstimatorState:
        p = self.plant
        return EstimatorState(z=[0.0] * (p.n + p.q + p.m), n=p.n, q=p.q)

    def saturate(self, u: np.ndarray) -> np.ndarray:
        """``u`` (deviation) limited so that ``u0 + u`` stays within the actuator limit."""
        if self._bounds is None:
            return u
        lo, hi = np.array(self._bounds, dtype=float).T
        clipped: np.ndarray = np.clip(np.asarray(u, dtype=float), lo, hi)
        return clipped

    def _advance(
        self, s: EstimatorState, k: int, u_prev: Iterable[float] | None, applied: bool | None = None
    ) -> list[float]:
        """Predict over lost samples up to k, put the reported u(k-1) in; returns z as a list of floats.

        ``applied is False`` (the vehicle reports that the command for k-1 never acted): the last step
        assumed ``B0 u(k-1)`` over the interval's tail while the actuator held the reported deflection the
        whole interval, so ``x_hat(k)`` is corrected by ``B0 (held - u(k-1))``: the estimator steps with
        the held deflection, as the contract says, instead of learning a phantom fault.
        """
        last = s.k_last
        if last is not None and k <= last:
            raise ValueError(f"sample {k} is not newer than {last}")
        self._skipped = 0
        z = s.values()
        if last is not None:
            gap = k - last - 1
            if gap > self.max_gap:
                z = [0.0] * self._N
            elif gap > _GAP_IN_FLOATS:  # a long gap: one matrix power
                z = (np.linalg.matrix_power(self._predict_T, gap) @ np.array(z)).tolist()
                self._skipped = gap
            elif gap:
                rows = self._predict_rows
                for _ in range(gap):
                    z = [sum(map(mul, row, z)) for row in rows]
                self._skipped = gap
        if u_prev is not None and self._lags is None:
            held = [float(e) for e in u_prev]
            if applied is False:
                self._held_correction(z, held)
            z[self._nq :] = held
        return z

    def _held_correction(self, z: list[float], held: list[float]) -> None:
        """Redo the last step, and the samples predicted since, with the held deflection instead of u(k-1).

        The step at k-1 assumed ``B0 u(k-1)`` and each lost sample after it assumed the actuator held
        u(k-1); in fact it held ``held`` all along. With ``delta = held - u(k-1)`` the error in ``x_hat`` is
        ``B0 delta`` after the step, then ``A (.) + (B0 + B1) delta`` per predicted sample (f_hat is not
        affected: no innovation used u). Plain floats: a vehicle that never applies the monitor's commands (an
        observer's test rig, a load generator) makes this every sample.
        """
        self._correct_inputs(z, [h - p for h, p in zip(held, z[self._nq :], strict=True)])

    def _correct_inputs(self, z: list[float], delta: list[float]) -> None:
        """``x_hat`` in ``z`` corrected for an input that acted ``delta`` off what the last step assumed over the
        interval's tail (``B0 delta``), and held so over the samples predicted since (``A (.) + (B0 + B1) delta``
        each)."""
        correction = [sum(map(mul, row, delta)) for row in self._B0_rows]
        if self._skipped:
            drift = [sum(map(mul, row, delta)) for row in self._B01_rows]  # (B0 + B1) delta
            rows = self._A_rows
            for _ in range(self._skipped):
                correction = [sum(map(mul, row, correction)) + d for row, d in zip(rows, drift, strict=True)]
        for i, c in enumerate(correction):
            z[i] += c

    def _finish(
        self, s: EstimatorState, k: int, v: list[float], u: list[float], known: Sequence[float] | None = None
    ) -> StepResult:
        """``v = [x_hat; f_hat; u(k-1); y]`` and the u(k) that acted: eq. (5), then the new state (plus
        ``Gamma known`` with known inputs)."""
        w = v + u
        out = [sum(map(mul, row, w)) for row in self._O_rows]
        n, nq = s.n, self._nq
        z_next = out[:nq] + u
        gamma = self._gamma_rows
        if known is not None and gamma is not None:
            kv = [float(e) for e in known]
            for i, row in enumerate(gamma):
                z_next[i] += sum(map(mul, row, kv))
        reset = not all(map(math.isfinite, z_next))
        s.set_values([0.0] * self._N if reset else z_next)
        s.k_last = k
        f_hat = v[n:nq]
        if self._keep:
            keep = self._keep
            previous = s.f_reported if s.f_reported is not None and not reset else [0.0] * len(f_hat)
            f_hat = s.f_reported = [keep * p + (1.0 - keep) * f for p, f in zip(previous, f_hat, strict=True)]
        return StepResult(k, u, v[: self._n_reported], f_hat, out[nq:], self._skipped, reset)

    def step(
        self,
        s: EstimatorState,
        k: int,
        y: ArrayLike,
        u_prev: Iterable[float] | None = None,
        applied: bool | None = None,
        known: Sequence[float] | None = None,
    ) -> StepResult:
        """Process sample k in place and return the command. Raises ValueError for a stale or duplicate k.

        ``u_prev``: the deflection the vehicle reports at k (None: the estimator's own last command);
        ``applied``: whether that report shows the command for k-1 acted (False: see ``_advance``);
        ``known``: the known-input term vector at k (module docstring; ignored for a plant without known
        inputs). It changes the prediction only: the certificates are unchanged (it cancels in the error).
        """
        v = self._advance(s, k, u_prev, applied) + _floats(y)
        u = [sum(map(mul, row, v)) for row in self._U_rows]
        bounds = self._bounds
        if bounds is not None:
            u = [hi if e > hi else lo if e < lo else e for e, (lo, hi) in zip(u, bounds, strict=True)]
        return self._finish(s, k, v, u, known)

    def observe(
        self,
        s: EstimatorState,
        k: int,
        y: ArrayLike,
        u_now: ArrayLike,
        u_prev: Iterable[float] | None = None,
        known: Sequence[float] | None = None,
    ) -> StepResult:
        """Observe-only: eq. (5) with the u(k) the vehicle's own controller issued (no command computed).
        ``known``: as for ``step`` (the prediction only; the certificates are unchanged). After lost samples see
        ``_resume``."""
        u = _floats(u_now)
        ys = _floats(y)
        z = self._advance(s, k, u_prev)
        if self._skipped:
            self._resume(z, ys, u)
        return self._finish(s, k, z + ys, u, known)

    def _resume(self, z: list[float], y: list[float], u_prev: list[float]) -> None:
        """The first sample after lost ones, when the vehicle's own controller flies (observe-only, compensate).

        The prediction across the gap held the last deflection reported before it, but the vehicle's controller
        kept moving the surface, so the predicted state is off by what it did, and the first innovation would
        read that as a fault: on c172p's turn envelope, one sample of 1.1 deg after 20 samples lost in a turn
        (3 deg once, live). So the state is read from the outputs where they give it (``x_hat = C^-1 y``, the
        innovation then zero) and u(k-1), unknown, is taken as the deflection reported now; f_hat keeps its
        value. A fault that began inside the gap is learnt from the next samples' innovations instead."""
        if self._reseed is not None:
            for i, row in enumerate(self._reseed):
                z[i] = sum(map(mul, row, y))
        z[self._nq :] = u_prev

    def compensate(
        self,
        s: EstimatorState,
        k: int,
        y: ArrayLike,
        u_total: ArrayLike,
        c_prev: Iterable[float],
        known: Sequence[float] | None = None,
        c_in_force: Sequence[float] | None = None,
    ) -> tuple[StepResult, list[float]]:
        """The autopilot flies, the monitor compensates: eq. (5), and the compensation ``c(k) = G f_hat(k)`` that
        the vehicle adds to its autopilot's deflection after the link's delay. ``G`` is eq. (6)'s fault term for
        a controller that is not ours (``closed_loop.fault_compensation``: the input that leaves no steady-state
        output; ``-I`` for an actuator fault), not the design's K3, which assumes the design's ``K2 u(k-1)``.

        ``u_total``: the deflection in force at instant k as the vehicle reports it, its autopilot's new
        ``a(k)`` plus the compensation ``c(k-1)`` still in force; ``c_prev``: that ``c(k-1)``, as sent. Over
        the interval the autopilot's part acts from k h and the compensation's from k h + tau, so

            x+ = A x + (B0 + B1) a(k) + B0 c(k) + B1 c(k-1) = A x + B0 (a(k) + c(k)) + B1 (a(k) + c(k-1)),

        which is eq. (5) with u(k-1) := u_total and u(k) := u_total - c(k-1) + c(k). Why the report and not
        the autopilot's part alone: it is the deflection that acted, whoever commanded it; a compensation that
        was lost (the vehicle still holds an older one) is then only wrong in the split, by c(k-1) - c(k-2).
        The compensation uses the raw estimate (the loop's, not the low-passed reported one) and is limited to
        the actuator's limit; the vehicle clips the total at the surface's travel. ``known``: as for ``step``
        (the prediction only; the certificates are unchanged).

        ``c_in_force``: the compensation in force at k as the vehicle reports it, when it does. A compensation
        that did not act (late or lost) is then the contract's lost command: the last step assumed ``B0 c(k-1)``
        over the interval's tail where ``c_in_force`` acted, so ``x_hat`` is corrected by ``B0 (c_in_force -
        c(k-1))`` (and carried over the samples predicted since), and the split uses what is in force. Why:
        without it, a run of late compensations is a run of phantom inputs, which the next compensation
        answers: on c172p at 4x real time on a loaded machine, 30 late ones in a row swung it to the 25 deg stop,
        alternating sign, before it settled.
        """
        total = _floats(u_total)
        c_sent = [float(e) for e in c_prev]
        missed = None
        if c_in_force is not None:
            in_force = [float(e) for e in c_in_force]
            if any(abs(a - b) > 1e-4 * max(1.0, abs(b)) for a, b in zip(in_force, c_sent, strict=True)):
                missed = [a - b for a, b in zip(in_force, c_sent, strict=True)]
            c_sent = in_force
        z = self._advance(s, k, total)
        ys = _floats(y)
        if self._skipped:
            self._resume(z, ys, total)
        elif missed is not None:
            self._correct_inputs(z, missed)
        v = z + ys
        f_raw = v[s.n : self._nq]
        comp = [sum(map(mul, row, f_raw)) for row in self._compensation_rows]
        lim = self._lim
        if lim is not None:
            comp = [lim if c > lim else -lim if c < -lim else c for c in comp]
        u_now = [t - p + c for t, p, c in zip(total, c_sent, comp, strict=True)]
        return self._finish(s, k, v, u_now, known), comp
