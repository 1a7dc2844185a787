"""Parsers for the fault, delay and wind SPECs of the contract: what fault the vehicle suffers, what delay it
sees, what wind blows.

Both ``sim-vehicle`` (which applies them) and the monitor's replay/demo code (which scores a run against
them, and simulates one: ``monitor.model.simulate``) import these functions, so the grammar, and the seeded
draws each SPEC stands for, live in exactly one place. Everything here is pure: no clocks, no sockets, and
random draws are keyed by the seed (``tau(k)`` by ``(seed, k)``, so it is the same whichever order the
samples are asked for in); the one file read is a ``trace:FILE`` delay SPEC's.

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

Wind SPEC (the plant's disturbance ``d(k)``, held constant over each sample interval so the paper's
``Dd d(k)`` is exact; several joined by ``+`` add up)::

    paper                   the paper's oscillator: s(k+1) = [[0.9922, 0.1247], [-0.1247, 0.9922]] s(k),
                            s(0) = [0.01, 0], d(k) = 0.1 s1(k)   (the default)
    turbulence:SIGMA[:TAU]  seeded first-order Gauss-Markov gusts, standard deviation SIGMA (plant units),
                            correlation time TAU seconds (default 2): d(k+1) = a d(k) + sqrt(1 - a^2) SIGMA w(k),
                            a = exp(-h / TAU), d(0) ~ N(0, SIGMA^2)
    none                    no wind

Why Gauss-Markov: it is the discrete form of the Dryden spectrum's first-order shape, stationary from
k = 0, and each draw is keyed by ``(seed, k)`` so runs are reproducible.

Excitation SPEC (sim-vehicle's ``--excite``, an identification manoeuvre the vehicle flies on board; the
aircraft demo hands it over and counts its samples)::

    prbs:AMP:SECONDS        a seeded random binary sequence of trim +- AMP (degrees) for SECONDS
    none                    no manoeuvre (the empty string too)

Why errors are ``UserError``: a SPEC comes from a command line, so a typo must be one line that quotes it.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterator
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
    "Wind",
    "parse_wind_spec",
    "PAPER_ROTATION",
    "Excitation",
    "parse_excite_spec",
    "MIN_DWELL_S",
    "MAX_DWELL_S",
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

    @property
    def amount(self) -> float:
        """``value`` of a term that carries one (bias, ramp, loe: the parser requires it)."""
        if self.value is None:
            raise ValueError(f"a {self.kind} term without a value")
        return float(self.value)

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
                total += ev.amount
            elif ev.kind == "ramp":
                total += ev.amount * (k - ev.start)
        return total

    def f_vector(self, k: int, q: int = 1) -> list[float]:
        """``f(k)`` as the plant's fault vector: the elevator fault is its first component."""
        return [self.f(k)] + [0.0] * (q - 1)

    def effectiveness(self, k: int) -> float:
        """Elevator effectiveness at sample ``k`` (1 = healthy), the product of the active ``loe`` terms."""
        return math.prod(ev.amount for ev in self.events if ev.kind == "loe" and ev.active(k))

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
    if kind == "loe" and value is not None and not 0.0 <= value <= 1.0:
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


PAPER_ROTATION = np.array([[0.9922, 0.1247], [-0.1247, 0.9922]])
PAPER_S0 = np.array([0.01, 0.0])
PAPER_GAIN = 0.1


@dataclass(frozen=True)
class Wind:
    """A sum of wind terms; ``values()`` yields ``d(k)`` as a scalar gust on the plant's first wind input."""

    oscillator: bool = True
    sigma: float = 0.0
    tau: float = 2.0
    h: float = 1.0
    seed: int = 0

    def series(self, n: int) -> np.ndarray:
        """``d(0), ..., d(n-1)``: the first ``n`` values of ``values()``."""
        return np.fromiter(itertools.islice(self.values(), n), dtype=float, count=n)

    def values(self) -> Iterator[float]:
        """``d(0), d(1), ...`` without end (the daemon may run until a signal)."""
        s = PAPER_S0.copy()
        a = math.exp(-self.h / self.tau)
        rng = np.random.default_rng([self.seed, 0x3D1])
        gust = rng.normal(0.0, self.sigma) if self.sigma > 0 else 0.0
        while True:
            yield (PAPER_GAIN * float(s[0]) if self.oscillator else 0.0) + gust
            s = PAPER_ROTATION @ s
            if self.sigma > 0:
                gust = a * gust + math.sqrt(1 - a * a) * self.sigma * float(rng.normal())


def parse_wind_spec(text: str, h: float, seed: int = 0) -> Wind:
    """Parse a wind SPEC (module docstring); a typo is a one-line ``UserError`` quoting the SPEC."""

    def fail(why: str) -> UserError:
        return UserError(f"bad wind SPEC '{text}': {why} (expected paper, none, turbulence:SIGMA[:TAU], joined by '+')")

    oscillator, sigma, tau = False, 0.0, 2.0
    for term in text.strip().lower().split("+"):
        kind, _, rest = term.strip().partition(":")
        if kind == "none" and not rest:
            continue
        if kind == "paper" and not rest:
            oscillator = True
            continue
        if kind != "turbulence":
            raise fail(f"unknown term '{term}'")
        try:
            numbers = [float(v) for v in rest.split(":")] if rest else []
        except ValueError:
            raise fail(f"'{rest}' are not numbers") from None
        if not 1 <= len(numbers) <= 2 or not all(math.isfinite(v) and v > 0 for v in numbers):
            raise fail("turbulence takes SIGMA > 0 and optionally TAU > 0")
        sigma = numbers[0]
        tau = numbers[1] if len(numbers) == 2 else tau
    return Wind(oscillator=oscillator, sigma=sigma, tau=tau, h=h, seed=seed)


MIN_DWELL_S = 0.2
MAX_DWELL_S = 0.8


@dataclass(frozen=True)
class Excitation:
    """A PRBS of +-``amplitude`` about trim for ``seconds`` of simulated time (``--excite prbs:AMP:SECONDS``).

    As an autopilot's system-identification mode does, the vehicle itself issues the elevator: a seeded random
    binary sequence of trim +- AMP (plant units, degrees) for the first SECONDS, then the trim deflection once
    (the manoeuvre ends where it started), and from then on it holds trim or follows commands from outside.

    The dwell (the time between two switches) is drawn uniformly from [0.2 s, 0.8 s], whole samples, at least
    one sample. Why: a switch every 0.2-0.8 s (mean 0.5 s) puts the sequence's power flat from DC to about
    1/(pi * 0.5 s) = 0.6 Hz, falling off above: it covers the short period (c172p at 100 kt: a 1-2 Hz mode that
    settles in ~0.6 s) and, for runs of a few minutes, the phugoid (~25 s period) too; a fixed-clock PRBS would
    have to pick one bit length for both. The draws come from ``(seed, "excite")`` only, so the same seed gives
    the same manoeuvre whatever the link does.

    Each level is issued at its sample k and applied after the drawn delay tau(k), like ``--autopilot``'s
    commands, and the sample's ACTUATOR_OUTPUT_STATUS reports the deflection issued (the contract's observe-only
    meaning), so a tlog of the run holds input and output side by side for ``fault-monitor analyse``.
    """

    amplitude: float
    seconds: float

    def samples(self, h: float) -> int:
        """How many samples carry a PRBS level (the next one returns to trim)."""
        return max(1, int(round(self.seconds / h)))

    def signs(self, h: float, seed: int, dwell: tuple[float, float] = (MIN_DWELL_S, MAX_DWELL_S)) -> list[int]:
        """+1/-1 per sample for ``samples(h)`` samples: seeded random switching with dwell in ``dwell`` seconds
        ([0.2, 0.8] s: the elevator's; a mission's throttle PRBS dwells longer, as an engine answers in seconds)."""
        n = self.samples(h)
        rng = np.random.default_rng([seed, 0xE7C1])
        shortest = max(1, int(math.ceil(dwell[0] / h - 1e-9)))
        longest = max(shortest, int(math.floor(dwell[1] / h + 1e-9)))
        sign = 1 if rng.random() < 0.5 else -1
        out: list[int] = []
        while len(out) < n:
            out.extend([sign] * int(rng.integers(shortest, longest + 1)))
            sign = -sign
        return out[:n]

    def __str__(self) -> str:
        return f"prbs:{self.amplitude:g}:{self.seconds:g}"


def parse_excite_spec(text: str | None) -> Excitation | None:
    """``prbs:AMP:SECONDS`` (AMP degrees > 0, SECONDS > 0) -> ``Excitation``; None or "none" -> None."""
    if text is None or str(text).strip().lower() in ("", "none"):
        return None
    kind, _, rest = str(text).strip().lower().partition(":")
    parts = rest.split(":")
    try:
        numbers = [float(v) for v in parts]
    except ValueError:
        numbers = []
    if kind != "prbs" or len(numbers) != 2 or not all(math.isfinite(v) and v > 0 for v in numbers):
        raise UserError(
            f"bad --excite SPEC '{text}': expected prbs:AMP:SECONDS with AMP (deg) and SECONDS > 0, e.g. prbs:1:60"
        )
    return Excitation(amplitude=numbers[0], seconds=numbers[1])
