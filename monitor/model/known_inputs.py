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

Why they change no certificate: a known input enters the plant and the observer alike, so it cancels in the
estimation error; the gains and their certificates are those of the plant without them (the table is left out
of the plant's digest). Why continuous plants only: ``Gamma`` needs ``A_c``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import UserError
from monitor.model.discretize import integral_expm

__all__ = ["KNOWN_TERMS", "KnownInputs", "parse_known_inputs", "bank_gravity", "euler_pitch_rate"]

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

    def vector(self, values: Mapping[str, float]) -> list[float] | None:
        """The continuous-time term vector (state units) at one sample; None when a value it reads is missing
        or not finite (the estimator then predicts without it)."""
        if any(not math.isfinite(values.get(name, math.nan)) for name in self.names):
            return None
        out = [0.0] * self.gamma.shape[0]
        for term in self.terms:
            out[self.index[term]] += KNOWN_TERMS[term].fn(values)
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
    extra = sorted(set(table) - {"terms"})
    if extra:
        raise UserError(f"{source}: key '{key}.{extra[0]}' is unknown (allowed: terms)")
    key = "known_inputs.terms"
    terms = table.get("terms")
    if not isinstance(terms, list) or not terms or not all(isinstance(t, str) for t in terms):
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
    _, gamma = integral_expm(A_c, h)
    others = tuple(s for s in names if s not in outputs)
    return KnownInputs(terms=tuple(terms), gamma=gamma, index=index, names=tuple(names), signals=others)
