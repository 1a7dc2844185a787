"""Parsers for the fault and delay SPECs of the contract: what fault the vehicle suffers, what delay it sees.

Both ``sim-vehicle`` (which applies them) and the monitor's replay/demo code (which scores a run against
them) import these functions, so the grammar lives in exactly one place. Everything here is pure: no
clocks, no sockets, and random draws are keyed by ``(seed, k)``, so ``tau(k)`` is the same whichever
order the samples are asked for in.

Fault SPEC (plant units, sample index ``k``; several joined by ``+``)::

    bias:2@20        f(k) = 2 for k >= 20                        (through D_cf, the paper's model)
    bias:2@20-60     f(k) = 2 for 20 <= k < 60 (intermittent; the end is exclusive)
    ramp:0.1@20      f(k) = 0.1 (k - 20) for k >= 20 (0 at onset)  (through D_cf)
    loe:0.5@20       elevator effectiveness x0.5 from k = 20      (acts on the deflection)
    stuck@30         elevator frozen where it is at t = 30 h      (acts on the deflection)
    stuck:5@30       elevator frozen at 5 (plant units) from k = 30
    none             no fault (the empty string too)

Every kind accepts the ``@START-END`` form. Additive faults add up, ``loe`` factors multiply, and when
several ``stuck`` overlap the earliest-starting one holds.

Delay SPEC (seconds of simulated time, total sensor -> actuator)::

    const:0.2   uniform:0:0.46   normal:0.2:0.05 (clipped at 0)   trace:FILE (one value per line, cycled)

Why errors are ``UserError``: a SPEC comes from a command line, so a typo must be one line that quotes it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import UserError

__all__ = [
    "FaultEvent",
    "FaultSchedule",
    "parse_fault_spec",
    "DelaySampler",
    "parse_delay_spec",
    "FAULT_KINDS",
    "DELAY_KINDS",
]

FAULT_KINDS = ("bias", "ramp", "loe", "stuck")
DELAY_KINDS = ("const", "uniform", "normal", "trace")

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_FAULT_RE = re.compile(rf"^(?P<kind>[a-z]+)(?::(?P<value>{_NUMBER}))?@(?P<start>\d+)(?:-(?P<end>\d+))?$")


@dataclass(frozen=True)
class FaultEvent:
    """One term of a fault SPEC, active on samples ``start <= k < end`` (``end`` None: forever)."""

    kind: str
    value: float | None
    start: int
    end: int | None = None

    def active(self, k: int) -> bool:
        return k >= self.start and (self.end is None or k < self.end)

    def __str__(self) -> str:
        value = "" if self.value is None else f":{self.value:g}"
        end = "" if self.end is None else f"-{self.end}"
        return f"{self.kind}{value}@{self.start}{end}"


@dataclass(frozen=True)
class FaultSchedule:
    """A parsed fault SPEC: ask it, sample by sample, what the elevator fault is.

    ``f(k)`` is the additive fault (plant units) that enters through ``D_cf`` and is held constant over
    ``[k h, (k+1) h)``, so the paper's discrete ``Df f(k)`` is exact. ``effectiveness(k)`` and
    ``stuck(k)`` describe the faults that act on the deflection itself.
    """

    events: tuple[FaultEvent, ...] = ()

    def f(self, k: int) -> float:
        """The additive elevator fault at sample ``k`` (bias + ramp), plant units."""
        total = 0.0
        for ev in self.events:
            if not ev.active(k):
                continue
            if ev.kind == "bias":
                total += float(ev.value)  # type: ignore[arg-type]
            elif ev.kind == "ramp":
                total += float(ev.value) * (k - ev.start)  # type: ignore[operator]
        return total

    def f_vector(self, k: int, q: int = 1) -> list[float]:
        """``f(k)`` as the plant's fault vector: the elevator fault is its first component."""
        return [self.f(k)] + [0.0] * (q - 1)

    def effectiveness(self, k: int) -> float:
        """Elevator effectiveness at sample ``k`` (1 = healthy), the product of the active ``loe`` terms."""
        return math.prod(float(ev.value) for ev in self.events if ev.kind == "loe" and ev.active(k))  # type: ignore[arg-type]

    def stuck(self, k: int) -> FaultEvent | None:
        """The ``stuck`` term holding the elevator at sample ``k`` (earliest start wins), or None."""
        active = [ev for ev in self.events if ev.kind == "stuck" and ev.active(k)]
        return min(active, key=lambda ev: ev.start) if active else None

    def active(self, k: int) -> bool:
        """Whether any fault acts at sample ``k`` (a ramp counts from its onset, where it is still 0)."""
        return any(ev.active(k) for ev in self.events)

    @property
    def onset(self) -> int | None:
        """The first sample at which any fault acts, or None without faults."""
        return min((ev.start for ev in self.events), default=None)

    @property
    def additive_only(self) -> bool:
        """True when every term enters through ``D_cf`` (so ``f(k)`` is the whole truth to score against)."""
        return all(ev.kind in ("bias", "ramp") for ev in self.events)

    def __str__(self) -> str:
        return "+".join(str(ev) for ev in self.events) or "none"


def parse_fault_spec(text: str | None) -> FaultSchedule:
    """Parse a fault SPEC (see the module docstring); ``None``, ``""`` and ``"none"`` mean no fault.

    >>> s = parse_fault_spec("bias:2@20-60+ramp:0.1@50")
    >>> s.f(19), s.f(20), s.f(55), s.f(60)
    (0.0, 2.0, 2.5, 1.0)
    >>> parse_fault_spec("loe:0.5@20").effectiveness(25)
    0.5
    """
    if text is None or text.strip().lower() in ("", "none"):
        return FaultSchedule()
    events = []
    for term in text.strip().split("+"):
        events.append(_parse_fault_term(term.strip(), text))
    return FaultSchedule(tuple(events))


def _parse_fault_term(term: str, spec: str) -> FaultEvent:
    def fail(why: str) -> UserError:
        return UserError(
            f"bad fault SPEC '{spec}': {why} (expected e.g. bias:2@20, bias:2@20-60, ramp:0.1@20, loe:0.5@20, "
            "stuck@30, joined by '+')"
        )

    match = _FAULT_RE.match(term)
    if not match:
        raise fail(f"cannot read term '{term}'")
    kind = match["kind"]
    if kind not in FAULT_KINDS:
        raise fail(f"unknown fault kind '{kind}' (known: {', '.join(FAULT_KINDS)})")
    value = float(match["value"]) if match["value"] is not None else None
    if value is not None and not math.isfinite(value):
        raise fail(f"value in '{term}' is not finite")
    if value is None and kind != "stuck":
        raise fail(f"'{kind}' needs a value, as in {kind}:VALUE@START")
    if kind == "loe" and not 0.0 <= value <= 1.0:  # type: ignore[operator]
        raise fail(f"loe effectiveness must be in [0, 1], got {value:g}")
    start = int(match["start"])
    end = int(match["end"]) if match["end"] is not None else None
    if end is not None and end <= start:
        raise fail(f"end {end} must come after start {start} in '{term}'")
    return FaultEvent(kind=kind, value=value, start=start, end=end)


@dataclass(frozen=True)
class DelaySampler:
    """A seeded distribution of the total sensor -> actuator delay, in seconds of simulated time.

    ``tau(k)`` is a pure function of ``(seed, k)``: the vehicle, a test and an evaluator all get the same
    draw for the same sample, whatever order they ask in.
    """

    kind: str
    params: tuple[float, ...]
    seed: int = 0
    trace: tuple[float, ...] = ()
    spec: str = ""

    def tau(self, k: int) -> float:
        if self.kind == "const":
            return self.params[0]
        if self.kind == "trace":
            return self.trace[k % len(self.trace)]
        rng = np.random.default_rng([self.seed, 0x7A0, k])
        if self.kind == "uniform":
            lo, hi = self.params
            return float(rng.uniform(lo, hi))
        mean, std = self.params
        return max(0.0, float(rng.normal(mean, std)))

    @property
    def mean(self) -> float:
        """The nominal mean (for ``normal`` before clipping at 0; for a trace, of its values)."""
        if self.kind == "uniform":
            return 0.5 * (self.params[0] + self.params[1])
        if self.kind == "trace":
            return float(np.mean(self.trace))
        return self.params[0]

    @property
    def ceiling(self) -> float:
        """The largest delay the spec draws (``normal``: mean + 4 std, beyond which a draw is one in 30,000).

        Why a vehicle needs it: past one sample a command still acts when it arrives, and the ceiling is how
        long the vehicle waits for one before counting it late (its stale-command rule)."""
        if self.kind == "uniform":
            return self.params[1]
        if self.kind == "trace":
            return float(max(self.trace))
        if self.kind == "normal":
            return self.params[0] + 4.0 * self.params[1]
        return self.params[0]

    def __str__(self) -> str:
        return self.spec


def parse_delay_spec(text: str, seed: int = 0, base_dir: str | Path | None = None) -> DelaySampler:
    """Parse a delay SPEC (see the module docstring). ``trace:FILE`` is read now, relative to ``base_dir``.

    >>> parse_delay_spec("const:0.2").tau(7)
    0.2
    >>> d = parse_delay_spec("uniform:0:0.46", seed=3)
    >>> d.tau(5) == d.tau(5) and 0 <= d.tau(5) <= 0.46
    True
    """
    spec = text.strip()

    def fail(why: str) -> UserError:
        return UserError(
            f"bad delay SPEC '{text}': {why} (expected const:S, uniform:LO:HI, normal:MEAN:STD or trace:FILE)"
        )

    kind, _, rest = spec.partition(":")
    if kind not in DELAY_KINDS:
        raise fail(f"unknown kind '{kind}'")
    if kind == "trace":
        return DelaySampler(kind, (), seed, _read_trace(rest, base_dir, fail), spec)
    try:
        params = tuple(float(p) for p in rest.split(":"))
    except ValueError:
        raise fail(f"'{rest}' are not numbers") from None
    expected = {"const": 1, "uniform": 2, "normal": 2}[kind]
    if len(params) != expected:
        raise fail(f"'{kind}' takes {expected} number(s), got {len(params)}")
    if not all(math.isfinite(p) for p in params):
        raise fail("numbers must be finite")
    if kind in ("const", "uniform") and min(params) < 0:
        raise fail("a delay cannot be negative")
    if kind == "uniform" and params[0] > params[1]:
        raise fail(f"low {params[0]:g} is above high {params[1]:g}")
    if kind == "normal" and params[1] < 0:
        raise fail("the standard deviation cannot be negative")
    return DelaySampler(kind, params, seed, (), spec)


def _read_trace(name: str, base_dir: str | Path | None, fail) -> tuple[float, ...]:
    if not name:
        raise fail("trace needs a file name, as in trace:delays.txt")
    path = Path(name)
    if base_dir is not None and not path.is_absolute():
        path = Path(base_dir) / path
    try:
        lines = path.read_text("utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise fail(f"cannot read {path}: {exc.strerror if isinstance(exc, OSError) else exc}") from None
    values = []
    for number, line in enumerate(lines, 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            value = float(line)
        except ValueError:
            raise fail(f"{path}:{number}: '{line}' is not a number") from None
        if not math.isfinite(value) or value < 0:
            raise fail(f"{path}:{number}: delay {line} must be finite and >= 0")
        values.append(value)
    if not values:
        raise fail(f"{path} holds no delay values")
    return tuple(values)
