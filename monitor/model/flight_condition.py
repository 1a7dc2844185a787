"""Flight-condition quantities computed from measured signals: what an envelope may be scheduled on besides them.

A schedule variable is a measured signal of the points' signal maps (``airspeed``, ``roll``) or one of the
quantities below, each a fixed function of named measured signals (a closed list; no user expressions):

* ``bank_load_factor``: ``1 / cos(roll)`` (roll in degrees, clipped to +-85 deg), the load factor of a
  coordinated level turn at the measured bank. Why this and not the bank itself: a turn's trim moves with the
  load factor (the extra lift, so alpha and the elevator, grow with ``n - 1``; the body pitch rate of a level
  turn is ``g/V (n - 1/n)``), so trims interpolated on it are near linear where on the bank they are not (on
  c172p, at 30 deg of bank, linear in the bank between 0 and 45 deg puts the trim 1.8 times too far). And it is
  the same in a left and a right turn: one point at 45 deg serves both (the longitudinal trim of a light
  aircraft does not depend on the turn's direction). It is not the measured normal acceleration (which a gust
  or a pull-up moves): the schedule wants the steady condition.
* ``bank_load_factor_signed``: ``sign(roll) (1 / cos(roll) - 1)``: 0 wings level, the extra load factor of the
  turn with the bank's sign (right positive). For an aircraft whose left and right turns trim differently (a
  propeller's torque and slipstream: JSBSim's J3Cub trims about 0.4 deg of elevator apart in 45 deg turns either
  way, where c172p and t6texan2 do not differ measurably): its turn legs are flown both ways and each direction is
  interpolated on its own side, near linear as the unsigned one is.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

__all__ = ["DERIVED", "Derived", "needed_signals", "schedule_value"]

MAX_BANK_DEG = 85.0  # the bank is clipped here before 1/cos: a knife edge is no level turn


@dataclass(frozen=True)
class Derived:
    inputs: tuple[str, ...]  # the measured signals it reads
    unit: str
    fn: Callable[[Mapping[str, float]], float]


def _bank_load_factor(v: Mapping[str, float]) -> float:
    bank = max(-MAX_BANK_DEG, min(MAX_BANK_DEG, v["roll"]))
    return 1.0 / math.cos(math.radians(bank))


def _bank_load_factor_signed(v: Mapping[str, float]) -> float:
    return math.copysign(_bank_load_factor(v) - 1.0, v["roll"])


DERIVED: dict[str, Derived] = {
    "bank_load_factor": Derived(("roll",), "", _bank_load_factor),
    "bank_load_factor_signed": Derived(("roll",), "", _bank_load_factor_signed),
}


def needed_signals(names: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """The measured signals the schedule variables ``names`` read (a derived one: its inputs), each once."""
    out: list[str] = []
    for name in names:
        out += DERIVED[name].inputs if name in DERIVED else [name]
    return tuple(dict.fromkeys(out))


def schedule_value(name: str, values: Mapping[str, float]) -> float:
    """The value of schedule variable ``name`` in a sample's ``{signal: value}``; NaN when an input is absent."""
    derived = DERIVED.get(name)
    if derived is None:
        return float(values.get(name, math.nan))
    if any(not math.isfinite(values.get(s, math.nan)) for s in derived.inputs):
        return math.nan
    return derived.fn(values)
