"""Known inputs of a plant: terms the telemetry measures, added to the model's prediction each sample.

A plant file's optional table (docs/reference/file-formats.md)::

    [known_inputs]
    terms = ["bank_gravity", "euler_pitch_rate"]

names built-in terms from a closed list (no user expressions). Each is a pure function of the sample's measured
values (absolute, in the signal map's units: deg, deg/s, m/s) to a contribution to one state's derivative, in the
model's state units; the estimator adds ``Gamma @ terms(k)`` to its prediction of ``x_hat(k+1)``, with
``Gamma = int_0^h e^{A_c s} ds`` (the term held over the sample, integrated with the plant's own dynamics):

* ``bank_gravity``: ``alpha-dot += (g / V) cos(theta) (cos(phi) - 1)`` (deg/s): the share of gravity a banked
  wing no longer carries. Needs states ``alpha``, ``theta``, ``airspeed`` and the measured signal ``roll``. ``V``
  is floored at 10 m/s (a sample on the ground does not divide by zero).
* ``euler_pitch_rate``: ``theta-dot += q (cos(phi) - 1) - r sin(phi)`` (deg/s): the Euler pitch rate, where the
  model has ``theta-dot = q``. Needs states ``q``, ``theta`` and the measured signals ``roll`` and ``r``.

And measured inputs the model was identified with besides the elevator (``identify --known-input throttle``)::

    [known_inputs.linear]
    throttle = [0.0021, -0.046]    # its column of B_c: state units per percent

adds ``column * (throttle - throttle0)`` to the state's derivative, ``throttle0`` the trim in the plant's
``[signals] condition`` (for an envelope, interpolated between the points as the outputs' trims are). Why: the
throttle moves in every change of speed, and its pitching moment needs elevator; without it in the model, the
estimator reads that elevator as a fault (c172p slowing to approach speed: about 0.03 deg of f_hat per percent).
An optional lag::

    [known_inputs.lag]
    throttle = 1.0                 # seconds

passes the signal through a first-order lag of that time constant before its column acts (``identify`` picks it
from a grid, by the held-out fit): the engine's thrust, and the propeller's wash over the tail, follow the lever
in about a second. Without it the fit underrates the column (on c172p a third of the steady effect at 65 kt,
where JSBSim's trims give 0.04 deg of elevator per percent), and the slow-down read as 0.6 deg of fault.

Why they change no certificate: a known input enters the plant and the observer alike, so it cancels in the
estimation error; the gains and their certificates are those of the plant without them (the table is left out
of the plant's digest). Why continuous plants only: ``Gamma`` needs ``A_c``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.errors import UserError
from monitor.model.discretize import integral_expm

__all__ = [
    "KNOWN_TERMS",
    "KnownInputs",
    "parse_known_inputs",
    "bank_gravity",
    "euler_pitch_rate",
    "lag_factor",
    "lagged",
]

G = 9.81
MIN_AIRSPEED = 10.0  # m/s: the floor of V in bank_gravity


def bank_gravity(v: Mapping[str, float]) -> float:
    """``degrees((g / V) cos(theta) (cos(phi) - 1))``: alpha's rate (deg/s); roll and theta in deg, V in m/s."""
    speed = max(v["airspeed"], MIN_AIRSPEED)
    return math.degrees(G / speed * math.cos(math.radians(v["theta"])) * (math.cos(math.radians(v["roll"])) - 1.0))


def euler_pitch_rate(v: Mapping[str, float]) -> float:
    """``q (cos(phi) - 1) - r sin(phi)``: theta's rate beyond q (deg/s); q, r in deg/s, roll in deg."""
    phi = math.radians(v["roll"])
    return v["q"] * (math.cos(phi) - 1.0) - v["r"] * math.sin(phi)


@dataclass(frozen=True)
class _Term:
    state: str  # the state whose derivative it adds to
    states: tuple[str, ...]  # the outputs (states) it reads
    signals: tuple[str, ...]  # the measured signals beyond the outputs it reads
    fn: Callable[[Mapping[str, float]], float]


KNOWN_TERMS: dict[str, _Term] = {
    "bank_gravity": _Term("alpha", ("alpha", "theta", "airspeed"), ("roll",), bank_gravity),
    "euler_pitch_rate": _Term("theta", ("q", "theta"), ("roll", "r"), euler_pitch_rate),
}
_UNITS = {"alpha": "deg", "q": "deg/s", "theta": "deg", "airspeed": "m/s", "roll": "deg", "r": "deg/s"}


@dataclass(frozen=True, eq=False)
class KnownInputs:
    """The plant's known-input terms: ``gamma`` (n x n, the physical state) and where each term goes."""

    terms: tuple[str, ...]
    gamma: np.ndarray
    index: dict[str, int]  # term name -> the state index it adds to
    names: tuple[str, ...]  # every measured value the terms read (outputs and others)
    signals: tuple[str, ...]  # those that are not outputs: the assembler needs them as it needs the outputs
    # [known_inputs.linear]: measured signal -> its column of B_c (state units per signal unit), acting on the
    # signal's deviation from its trim (``trim``, the plant's [signals] condition)
    linear: dict[str, np.ndarray] = field(default_factory=dict)
    trim: dict[str, float] = field(default_factory=dict)
    # [known_inputs.lag]: a linear input's first-order lag (s) before its column acts: an engine's thrust follows
    # the throttle in about a second (the estimator lags the measured signal the same way; ``lag_factor``)
    lag: dict[str, float] = field(default_factory=dict)

    def vector(
        self,
        values: Mapping[str, float],
        trim: Mapping[str, float] | None = None,
        columns: Mapping[str, np.ndarray] | None = None,
    ) -> list[float] | None:
        """The continuous-time term vector (state units) at one sample; None when a value it reads is missing
        or not finite (the estimator then predicts without it). ``trim`` and ``columns``: the linear inputs'
        trims and columns, when not the plant's own (an envelope's, interpolated between its points)."""
        if any(not math.isfinite(values.get(name, math.nan)) for name in self.names):
            return None
        out = [0.0] * self.gamma.shape[0]
        for term in self.terms:
            out[self.index[term]] += KNOWN_TERMS[term].fn(values)
        trims = self.trim if trim is None else trim
        for name, column in (self.linear if columns is None else columns).items():
            out = [o + float(c) * (values[name] - trims[name]) for o, c in zip(out, column, strict=True)]
        return out


def parse_known_inputs(
    raw: dict[str, Any], source: str, C: np.ndarray, A_c: np.ndarray | None, h: float
) -> KnownInputs | None:
    """The ``[known_inputs]`` table of a plant file (None without one); every error is one line naming the key."""
    if "known_inputs" not in raw:
        return None
    table = raw["known_inputs"]
    key = "known_inputs"
    if not isinstance(table, dict):
        raise UserError(f"{source}: key '{key}' must be a table ([known_inputs] with terms = [...])")
    extra = sorted(set(table) - {"terms", "linear", "lag"})
    if extra:
        raise UserError(f"{source}: key '{key}.{extra[0]}' is unknown (allowed: terms, linear, lag)")
    if not table:
        raise UserError(f"{source}: [known_inputs] needs 'terms' or a [known_inputs.linear] table")
    key = "known_inputs.terms"
    terms = table.get("terms", [])
    if not isinstance(terms, list) or not all(isinstance(t, str) for t in terms) or ("terms" in table and not terms):
        raise UserError(f"{source}: key '{key}' must be a non-empty list of names ({', '.join(KNOWN_TERMS)})")
    for t in terms:
        if t not in KNOWN_TERMS:
            raise UserError(f"{source}: key '{key}' names '{t}', not a known term (known: {', '.join(KNOWN_TERMS)})")
    dup = [t for i, t in enumerate(terms) if t in terms[:i]]
    if dup:
        raise UserError(f"{source}: key '{key}' names '{dup[0]}' twice")
    if A_c is None:
        raise UserError(f"{source}: key '{key}' needs a continuous plant (form = \"continuous\": Gamma needs A_c)")
    signals = raw.get("signals")
    outputs = signals.get("outputs") if isinstance(signals, dict) else None
    measured = signals.get("measured") if isinstance(signals, dict) else None
    if not isinstance(outputs, list) or not isinstance(measured, dict):
        raise UserError(f"{source}: key '{key}' needs a [signals] table with outputs and [signals.measured]")
    state_of: dict[str, int] = {}
    for j, name in enumerate(outputs):
        row = C[j] if j < C.shape[0] else None
        if row is not None and np.count_nonzero(row) == 1 and float(row[np.flatnonzero(row)[0]]) == 1.0:
            state_of[str(name)] = int(np.flatnonzero(row)[0])
    index: dict[str, int] = {}
    names: list[str] = []
    for t in terms:
        term = KNOWN_TERMS[t]
        for s in term.states:
            if s not in state_of:
                raise UserError(
                    f"{source}: key '{key}': '{t}' needs state '{s}' among the outputs (a unit row of C); "
                    f"outputs: {', '.join(map(str, outputs))}"
                )
        for s in term.signals:
            if s not in measured:
                raise UserError(f"{source}: key '{key}': '{t}' needs '{s}' in [signals.measured] (ATTITUDE)")
        for s in (*term.states, *term.signals):
            unit = measured.get(s, {}).get("unit") if isinstance(measured.get(s), dict) else None
            if unit is not None and unit != _UNITS[s]:
                raise UserError(f"{source}: key '{key}': '{t}' needs '{s}' in {_UNITS[s]}, its signal is in {unit}")
            if s not in names:
                names.append(s)
        index[t] = state_of[term.state]
    linear, trim = _linear(table.get("linear"), dict(signals or {}), measured, outputs, A_c.shape[0], source)
    lag = _lag(table.get("lag"), linear, source)
    names += [s for s in linear if s not in names]
    _, gamma = integral_expm(A_c, h)
    others = tuple(s for s in names if s not in outputs)
    return KnownInputs(
        terms=tuple(terms),
        gamma=gamma,
        index=index,
        names=tuple(names),
        signals=others,
        linear=linear,
        trim=trim,
        lag=lag,
    )


def _lag(raw: Any, linear: dict[str, np.ndarray], source: str) -> dict[str, float]:
    """``[known_inputs.lag]``: ``signal = seconds`` (>= 0) for signals of ``[known_inputs.linear]``."""
    if raw is None:
        return {}
    key = "known_inputs.lag"
    if not isinstance(raw, dict):
        raise UserError(f"{source}: key '{key}' must be a table of signal = seconds")
    lag: dict[str, float] = {}
    for name, value in raw.items():
        if name not in linear:
            raise UserError(f"{source}: key '{key}.{name}': '{name}' has no column in [known_inputs.linear]")
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not (math.isfinite(value) and value >= 0):
            raise UserError(f"{source}: key '{key}.{name}' must be a number of seconds >= 0, got {value!r}")
        lag[name] = float(value)
    return lag


def lag_factor(lag_s: float, elapsed_s: float) -> float:
    """The weight of the new value in a first-order lag of time constant ``lag_s`` after ``elapsed_s`` (the
    exact step of ``T y' = u - y`` with ``u`` held): 1 without a lag."""
    return 1.0 if lag_s <= 0 else 1.0 - math.exp(-max(elapsed_s, 0.0) / lag_s)


def lagged(values: np.ndarray, k: np.ndarray, lag_s: float, h: float) -> np.ndarray:
    """``values`` (one per sample ``k``) through a first-order lag of ``lag_s`` seconds, started at the first
    value; each value is taken as held over the interval that ends at its sample (the estimator steps the same
    way, sample by sample), and a gap in ``k`` is one longer interval."""
    out = np.array(values, dtype=float)
    for i in range(1, len(out)):
        out[i] = out[i - 1] + lag_factor(lag_s, float(k[i] - k[i - 1]) * h) * (out[i] - out[i - 1])
    return out


def _linear(
    raw: Any, signals: dict[str, Any], measured: dict[str, Any], outputs: list[Any], n: int, source: str
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """``[known_inputs.linear]``: ``signal = [one number per state]``, each signal measured, not an output, with its
    trim in ``[signals] condition``."""
    if raw is None:
        return {}, {}
    key = "known_inputs.linear"
    if not isinstance(raw, dict) or not raw:
        raise UserError(f"{source}: key '{key}' must be a table of signal = [one number per state]")
    condition = signals.get("condition")
    linear: dict[str, np.ndarray] = {}
    trim: dict[str, float] = {}
    for name, column in raw.items():
        where = f"{source}: key '{key}.{name}'"
        if name not in measured:
            raise UserError(f"{where}: '{name}' is not in [signals.measured]")
        if name in outputs:
            raise UserError(
                f"{where}: '{name}' is an output; a known input is a measured signal the model does not have"
            )
        if (
            not isinstance(column, list)
            or len(column) != n
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in column)
        ):
            raise UserError(f"{where}: must be a list of {n} finite numbers (its column of B_c, one per state)")
        value = condition.get(name) if isinstance(condition, dict) else None
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            raise UserError(f"{where}: needs its trim, '{name}' in [signals] condition (identify writes it)")
        linear[name] = np.array(column, dtype=float)
        trim[name] = float(value)
    return linear, trim
