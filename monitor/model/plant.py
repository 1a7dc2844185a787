"""Plant descriptions: loading, validating and naming the sampled plant with uncertain short delay.

A plant file is TOML in one of two forms (docs/reference/file-formats.md):

* ``form = "continuous"``: ``A_c, B_c, D_cf, D_cd, C`` plus ``h, tau_min, tau_max``. The delay-aware
  discrete model follows exactly from it (``monitor.model.discretize``); the simulator integrates it.
* ``form = "discrete"``: ``A, B0, B1, C, Df, Dd`` plus ``h, tau_min, tau_max`` and optionally ``delta``
  and ``E``. The delay then enters only as the paper's norm-bounded uncertainty
  ``B0(tau) = B0 + F E``, ``B1(tau) = B1 - F E``, ``sigma_max(F) <= delta``.

Why be strict: a silently ignored typo in a key (``tau_mx``) would design for the wrong plant, so every
unknown key, wrong shape, non-finite number or negative delay is a one-line ``UserError`` naming the key
and the file. A delay interval that reaches past h gives a plant with the commands in flight in its state
(``Lags``, ``monitor.model.long_delay``). An envelope file (``form = "envelope"``, several operating points:
``monitor.model.envelope``) is refused here with a line that says so; its points are read by this module.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import UserError
from monitor.model.discretize import ContinuousModel, discretize
from monitor.model.known_inputs import KnownInputs, parse_known_inputs
from monitor.wire import TURBULENCE_LEVELS

__all__ = [
    "Plant",
    "Lags",
    "Disturbance",
    "ContinuousModel",
    "Actuator",
    "load_plant",
    "parse_plant",
    "plant_from_table",
    "with_tau_max",
    "preset_names",
]

PRESETS = {"paper": "paper.toml", "paper-continuous": "paper-continuous.toml"}

_COMMON_KEYS = {
    "form",
    "name",
    "description",
    "unit",
    "h",
    "tau_min",
    "tau_max",
    "C",
    "actuator",
    "disturbance",
    "signals",
    "identification",
    "known_inputs",
}
_CONTINUOUS_KEYS = _COMMON_KEYS | {"A_c", "B_c", "D_cf", "D_cd"}
_DISCRETE_KEYS = _COMMON_KEYS | {"A", "B0", "B1", "Df", "Dd", "delta", "E"}
_ACTUATOR_KEYS = {"limit", "rate_limit"}
_DISTURBANCE_KEYS = {"sigma", "time_constant", "turbulence", "source"}
# tables that say nothing about the dynamics: left out of the digest, so gains stay valid when they are edited.
# [identification] is what `fault-monitor identify` found (source log, fit, modes): information, never maths.
# [known_inputs] (monitor.model.known_inputs) cancels in the estimation error: the gains do not depend on it.
_NOT_DYNAMICS = ("signals", "identification", "known_inputs")


@dataclass(frozen=True)
class Actuator:
    """Physical limits of the elevator, used by the simulator (None: unlimited)."""

    limit: float | None = None
    rate_limit: float | None = None


@dataclass(frozen=True)
class Disturbance:
    """The air the plant flies in: the input ``d`` (through ``D_cd``/``Dd``) as a first-order Gauss-Markov process.

    ``d' = -d / time_constant + white noise``, with standard deviation ``sigma`` (plant units): what a gust field
    looks like through one input at one flight condition (a Dryden vertical gust, seen as an angle of attack,
    is close to it). ``fault-monitor identify`` measures it; ``detectability`` scales it to other levels, and the
    level it was measured in (``turbulence``) decides the reported estimate's default low-pass (``design``).
    """

    sigma: float
    time_constant: float
    turbulence: str | None = None


@dataclass(frozen=True, eq=False)
class Plant:
    """A validated plant. ``A, B0, B1, Df, Dd`` are the discrete matrices at the nominal delay.

    For the continuous form ``B0``/``B1`` are the exact split at ``tau_bar`` (mid-interval); for the
    discrete form they are the printed matrices. ``continuous`` is None for the discrete form.
    """

    name: str
    form: str
    h: float
    tau_min: float
    tau_max: float
    A: np.ndarray
    B0: np.ndarray
    B1: np.ndarray
    C: np.ndarray
    Df: np.ndarray
    Dd: np.ndarray
    continuous: ContinuousModel | None = None
    delta: float | None = None
    E: np.ndarray | None = None
    unit: str = "deg"
    description: str = ""
    actuator: Actuator = field(default_factory=Actuator)
    disturbance: Disturbance | None = None  # the [disturbance] table: the gust input's size and spectrum
    source: str = "<memory>"
    digest: str = ""
    signals: dict[str, Any] | None = None  # the raw [signals] table (validated by monitor.link.signals)
    raw: dict[str, Any] | None = field(default=None, repr=False)  # the parsed TOML, to derive variants
    lags: Lags | None = None  # tau_max >= h: the commands in flight are in the state (monitor.model.long_delay)
    known_inputs: KnownInputs | None = None  # [known_inputs]: terms added to the prediction (physical state)

    @property
    def physical(self) -> Plant:
        """The plant without the commands in flight (state x only): what a simulator integrates."""
        return self.lags.base if self.lags is not None else self

    @property
    def tau_bar(self) -> float:
        """Nominal delay: the middle of the interval, as the paper takes it."""
        return 0.5 * (self.tau_min + self.tau_max)

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        return int(self.B0.shape[1])

    @property
    def l(self) -> int:  # noqa: E743 - the paper's name for the output dimension
        return int(self.C.shape[0])

    @property
    def q(self) -> int:
        return int(self.Df.shape[1])

    @property
    def p(self) -> int:
        return int(self.Dd.shape[1])


@dataclass(frozen=True, eq=False)
class Lags:
    """How a plant whose delay reaches past one sample carries its commands in flight.

    ``base`` is the sampled plant on ``x`` alone (its delay curve ``G(a)`` is the ``B0`` of a delay
    ``a < h``); ``first`` and ``last`` are the whole samples of ``tau_min`` and ``tau_max``. The lagged
    plant's state is ``[x; u(k-2); ...; u(k-last-1)]`` and its ``A, B0, B1`` are those at the nominal delay.
    """

    base: Plant
    first: int
    last: int


def preset_names() -> list[str]:
    return sorted(PRESETS)


def load_plant(spec: str | Path) -> Plant:
    """Load a preset by name (``paper``, ``paper-continuous``) or a plant TOML file by path."""
    spec_str = str(spec)
    if spec_str in PRESETS:
        text = resources.files("monitor.presets").joinpath(PRESETS[spec_str]).read_text("utf-8")
        return parse_plant(text, source=f"preset:{spec_str}")
    path = Path(spec_str)
    if not path.is_file():
        raise UserError(f"plant '{spec_str}' is neither a preset ({', '.join(preset_names())}) nor a readable file")
    try:
        text = path.read_text("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read plant file: {exc}") from None
    return parse_plant(text, source=str(path))


def parse_plant(text: str, source: str = "<memory>") -> Plant:
    """Parse and validate plant TOML text; ``source`` names the file in every error."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{source}: not valid TOML: {exc}") from None
    return plant_from_table(raw, source)


def with_tau_max(plant: Plant, tau_max: float) -> Plant:
    """The same plant with another upper delay bound: what a plant file with that ``tau_max`` would give.

    The nominal split moves with the interval's middle (continuous form; the discrete form keeps its
    printed B0 as the nominal), and the digest is that of the edited file, so gains designed for the
    variant are recognised by ``run`` when the user writes the file.
    """
    if plant.raw is None:
        raise ValueError("this plant was not built from a plant table; it has no variants")
    return plant_from_table({**plant.raw, "tau_max": float(tau_max)}, f"{plant.source} with tau_max = {tau_max:g}")


def plant_from_table(raw: dict[str, Any], source: str) -> Plant:
    """Validate a parsed plant table (see the module docstring) and build the Plant."""
    form = raw.get("form")
    if form == "envelope":
        raise UserError(
            f'{source}: is an envelope plant file (form = "envelope": the plant at several operating points); '
            "design and verify take it, this command takes a single-point plant file"
        )
    if form not in ("continuous", "discrete"):
        raise UserError(f'{source}: key \'form\' must be "continuous" or "discrete", got {form!r}')
    allowed = _CONTINUOUS_KEYS if form == "continuous" else _DISCRETE_KEYS
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise UserError(
            f"{source}: unknown key '{unknown[0]}' for form '{form}' (allowed: {', '.join(sorted(allowed))})"
        )
    reader = _Reader(raw, source)
    if "identification" in raw and not isinstance(raw["identification"], dict):
        raise UserError(
            f"{source}: key 'identification' must be a table ([identification]: how the plant was "
            f"identified, information only), got {raw['identification']!r}"
        )
    h = reader.scalar("h", positive=True)
    tau_min = reader.scalar("tau_min")
    tau_max = reader.scalar("tau_max")
    if not 0.0 <= tau_min <= tau_max:
        raise UserError(
            f"{source}: keys 'tau_min'/'tau_max' must satisfy 0 <= tau_min <= tau_max (got {tau_min}, {tau_max})"
        )
    if tau_max >= h:
        return _lagged_plant(raw, source, h, tau_min, tau_max)
    C = reader.matrix("C")
    n = C.shape[1]
    common: dict[str, Any] = dict(
        name=str(raw.get("name", Path(source).stem)),
        form=form,
        h=h,
        tau_min=tau_min,
        tau_max=tau_max,
        C=C,
        unit=str(raw.get("unit", "deg")),
        description=str(raw.get("description", "")),
        actuator=reader.actuator(),
        disturbance=reader.disturbance(),
        source=source,
        digest=_digest({k: v for k, v in raw.items() if k not in _NOT_DYNAMICS}),
        signals=raw.get("signals"),
        raw=raw,
    )
    if form == "continuous":
        A_c = reader.matrix("A_c", rows=n, cols=n)
        B_c = reader.matrix("B_c", rows=n)
        D_cf = reader.matrix("D_cf", rows=n)
        D_cd = reader.matrix("D_cd", rows=n)
        model = ContinuousModel(A_c=A_c, B_c=B_c, D_cf=D_cf, D_cd=D_cd)
        d = discretize(model, h, 0.5 * (tau_min + tau_max))
        known = parse_known_inputs(raw, source, C, A_c, h)
        return Plant(A=d.A, B0=d.B0, B1=d.B1, Df=d.Df, Dd=d.Dd, continuous=model, known_inputs=known, **common)
    A = reader.matrix("A", rows=n, cols=n)
    B0 = reader.matrix("B0", rows=n)
    B1 = reader.matrix("B1", rows=n, cols=B0.shape[1])
    Df = reader.matrix("Df", rows=n)
    Dd = reader.matrix("Dd", rows=n)
    delta = reader.scalar("delta", positive=True) if "delta" in raw else None
    E = reader.matrix("E") if "E" in raw else None
    parse_known_inputs(raw, source, C, None, h)  # a discrete plant with [known_inputs]: one line
    if E is not None and E.shape[1] != B0.shape[1]:
        raise UserError(f"{source}: key 'E' must have {B0.shape[1]} column(s) (one per input), got {E.shape[1]}")
    if E is not None and E.shape[0] != n:
        raise UserError(f"{source}: key 'E' must have {n} row(s) (F is n x n, D = I), got {E.shape[0]}")
    return Plant(A=A, B0=B0, B1=B1, Df=Df, Dd=Dd, delta=delta, E=E, **common)


def _lagged_plant(raw: dict[str, Any], source: str, h: float, tau_min: float, tau_max: float) -> Plant:
    """A plant whose delay interval reaches past h: the commands in flight join the state.

    The base is the same file read with a zero delay; its curve ``G(a)`` is exact for the continuous form
    and that of the reconstructed continuous model for the discrete form (the paper's ``B0 + F E`` is a
    first-order picture of one interval only). Refused with one line when the interval spans more whole
    samples than a certificate can enumerate in reasonable time.
    """
    from monitor.model.discretize import reconstruct_continuous
    from monitor.model.long_delay import MAX_LAG_PARTS, curve_of, lag_point, lag_realization, lag_span, lagged_matrices

    first, last = lag_span(h, tau_min, tau_max)
    if last - first + 1 > MAX_LAG_PARTS:
        raise UserError(
            f"{source}: keys 'tau_min'/'tau_max' = [{tau_min:g}, {tau_max:g}] s span {last - first + 1} whole samples "
            f"of h = {h:g} s; at most {MAX_LAG_PARTS} can be certified (each multiplies the certificate's vertices): "
            f"narrow the interval (tau_max - tau_min < {MAX_LAG_PARTS - 1} h always fits)"
        )
    base = plant_from_table({**raw, "tau_min": 0.0, "tau_max": 0.0}, source)
    model = base.continuous or reconstruct_continuous(base.A, base.B0 + base.B1, base.Df, base.Dd, h)
    curve = curve_of(model.A_c, model.B_c, h)
    nominal = lag_point(curve, h, tau_min, tau_max, 0.5 * (tau_min + tau_max))
    A, B0, B1 = lag_realization(nominal, base.A, curve(0.0), first, last)
    C, Df, Dd = lagged_matrices(base.C, base.Df, base.Dd, base.m, last)
    return Plant(
        name=base.name,
        form=base.form,
        h=h,
        tau_min=tau_min,
        tau_max=tau_max,
        A=A,
        B0=B0,
        B1=B1,
        C=C,
        Df=Df,
        Dd=Dd,
        unit=base.unit,
        description=base.description,
        actuator=base.actuator,
        disturbance=base.disturbance,
        source=source,
        digest=_digest({k: v for k, v in raw.items() if k not in _NOT_DYNAMICS}),
        signals=base.signals,
        raw=raw,
        lags=Lags(base=base, first=first, last=last),
        known_inputs=base.known_inputs,
    )


class _Reader:
    """Typed access to the raw TOML table with errors that name the key and the file."""

    def __init__(self, raw: dict[str, Any], source: str) -> None:
        self.raw = raw
        self.source = source

    def _fail(self, key: str, what: str) -> UserError:
        return UserError(f"{self.source}: key '{key}' {what}")

    def scalar(self, key: str, positive: bool = False) -> float:
        if key not in self.raw:
            raise self._fail(key, "is missing")
        value = self.raw[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self._fail(key, f"must be a number, got {value!r}")
        value = float(value)
        if not np.isfinite(value):
            raise self._fail(key, f"must be finite, got {value}")
        if positive and value <= 0:
            raise self._fail(key, f"must be positive, got {value}")
        return value

    def matrix(self, key: str, rows: int | None = None, cols: int | None = None) -> np.ndarray:
        if key not in self.raw:
            raise self._fail(key, "is missing")
        value = self.raw[key]
        if not isinstance(value, list) or not value or not all(isinstance(r, list) and r for r in value):
            raise self._fail(key, "must be a non-empty list of rows, e.g. [[1.0], [2.0]]")
        widths = {len(r) for r in value}
        if len(widths) != 1:
            raise self._fail(key, f"has rows of different lengths {sorted(widths)}")
        if any(isinstance(x, bool) or not isinstance(x, (int, float)) for r in value for x in r):
            raise self._fail(key, "must contain only numbers")
        arr = np.array(value, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise self._fail(key, "contains a non-finite number (nan or inf)")
        if rows is not None and arr.shape[0] != rows:
            raise self._fail(key, f"must have {rows} row(s), got shape {arr.shape[0]}x{arr.shape[1]}")
        if cols is not None and arr.shape[1] != cols:
            raise self._fail(key, f"must have {cols} column(s), got shape {arr.shape[0]}x{arr.shape[1]}")
        return arr

    def disturbance(self) -> Disturbance | None:
        if "disturbance" not in self.raw:
            return None
        table = self.raw["disturbance"]
        if not isinstance(table, dict):
            raise self._fail("disturbance", "must be a table ([disturbance] with sigma and time_constant)")
        unknown = sorted(set(table) - _DISTURBANCE_KEYS)
        if unknown:
            raise self._fail(
                f"disturbance.{unknown[0]}", f"is unknown (allowed: {', '.join(sorted(_DISTURBANCE_KEYS))})"
            )
        sub = _Reader(table, self.source)
        level = table.get("turbulence")
        if level is not None and level not in TURBULENCE_LEVELS:
            raise self._fail("disturbance.turbulence", f"must be one of {', '.join(TURBULENCE_LEVELS)}, got {level!r}")
        return Disturbance(
            sigma=sub.scalar("sigma", positive=True),
            time_constant=sub.scalar("time_constant", positive=True),
            turbulence=level,
        )

    def actuator(self) -> Actuator:
        table = self.raw.get("actuator", {})
        if not isinstance(table, dict):
            raise self._fail("actuator", "must be a table")
        unknown = sorted(set(table) - _ACTUATOR_KEYS)
        if unknown:
            raise self._fail(f"actuator.{unknown[0]}", f"is unknown (allowed: {', '.join(sorted(_ACTUATOR_KEYS))})")
        sub = _Reader(table, self.source)
        limit = sub.scalar("limit", positive=True) if "limit" in table else None
        rate = sub.scalar("rate_limit", positive=True) if "rate_limit" in table else None
        return Actuator(limit=limit, rate_limit=rate)


def _digest(raw: dict[str, Any]) -> str:
    """A hash of the plant's content (not its formatting), so gains can say which plant they are for.

    The ``[signals]`` and ``[identification]`` tables are left out: which MAVLink fields carry y and u, or how
    the matrices were found, does not change the dynamics.
    """
    canonical = json.dumps(raw, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(canonical.encode()).hexdigest()[:16]
