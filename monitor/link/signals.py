"""The signal map: which MAVLink values are the plant's outputs, its actuator, its command and its instant.

A ``[signals]`` table in the plant file, or a file of its own (``--signals FILE``, same table)::

    [signals]
    instant = "AOA_SSA"                    # the message whose time field defines sample k
    outputs = ["alpha"]                    # y_1 .. y_l, in the order of the plant's C rows
    actuator = ["elevator"]                # u_1 .. u_m as the vehicle reports them
    record = ["alpha", "q", "elevator"]    # recorded as /vehicle/<id>/measured/<name> (default: all)

    [signals.measured]                     # name = { field = "MESSAGE.field[index]", scale, offset, unit }
    alpha = { field = "AOA_SSA.AOA", unit = "deg" }
    q = { field = "ATTITUDE.pitchspeed", scale = 57.29577951308232, unit = "deg/s" }
    elevator = { field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }

    [signals.command]                      # what the monitor sends (run without --observe)
    message = "SET_ACTUATOR_CONTROL_TARGET"
    channels = [1]                         # controls[] index of u_1 .. u_m
    full_scale = [30.0]                    # plant units per normalised unit (controls are in [-1, 1])
    group = 0

``operating_point = { alpha = 2.31, q = 0.0, ..., elevator = -4.3 }`` (optional; what ``fault-monitor identify``
writes): the trim the plant was identified about, in plant units, naming every output and actuator signal.
The estimator then works on deviations ``y - y0`` and ``u - u0`` and commands go out as absolute deflections
``u0 + u`` (saturated at the actuator limit as absolute values). Absent: zero (the values are the deviations).

``range = [low, high]`` is the signal's physical envelope: a sample whose estimator inputs are not finite
or fall outside it is rejected (counted) before the estimator. A value in plant units is
``scale * MESSAGE.field[index] + offset`` (e.g. a servo PWM in us:
``scale = 0.06, offset = -90`` maps 1000..2000 us to -30..30 deg). A message with ``time_usec`` or
``time_boot_ms`` is matched to its sampling instant by that field (contract: AOA_SSA's ``time_usec`` is the
instant, ATTITUDE matches by ``time_boot_ms``, ACTUATOR_OUTPUT_STATUS by ``time_usec``). A message without
one (VFR_HUD) cannot be matched: its signals are *latest values* (sample and hold): a sample takes the
newest value received from its vehicle before the sample is processed, if that value is at most ``hold``
seconds of the vehicle's clock older than the sample (default 1 s; see monitor/link/assembly.py). ``hold``
on a message WITH a time field makes it a latest value too, stamped by its own time: how a slower stream
joins faster samples (a 10 Hz position in 50 Hz samples, ``hold = 0.15``). The instant and the actuator
report need a time field and no hold. Anything unknown (a message, a field, an index, a key)
is a one-line error naming it.

Why names and not just a list of fields: the recording and the replay report read signals by name
(``alpha`` gives ``peak_alpha``), and a second airframe names its own.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field as dc_field
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.link.derived import Derivation, parse_derivation
from monitor.link.dialect import MessageLayout, layout_by_name
from monitor.wire.mavlink import ELEVATOR_FULL_SCALE_DEG, PITCH_CHANNEL
from monitor.wire.telemetry import INSTANT_MESSAGE, field_of

__all__ = [
    "Signal",
    "CommandMap",
    "SignalMap",
    "DEFAULT_SIGNALS_TOML",
    "contract_signals_toml",
    "default_signal_map",
    "parse_signals",
    "load_signals_file",
    "signals_for_plant",
    "Layouts",
    "MAVLINK",
]


class Layouts:
    """Where the names of a signal map are looked up: the MAVLink dialect (links, tlogs), or the messages a
    DataFlash log declares in its FMT records (``monitor.link.dataflash``). Same map syntax, same checks."""

    kind = "MAVLink"
    instant_field = "time_usec"  # the microsecond field an instant message needs

    def __call__(self, name: str) -> MessageLayout | None:
        return layout_by_name(name)

    def unknown(self, name: str) -> str:
        return f"unknown MAVLink message '{name}' (ardupilotmega dialect)"

    def no_map(self) -> str | None:
        """Why there is no default signal map here (None: the contract's default applies)."""
        return None


MAVLINK = Layouts()


def contract_signals_toml(
    measured: Sequence[str],
    outputs: Sequence[str] | None = None,
    actuator: Sequence[str] = ("elevator",),
    ranges: bool = True,
) -> str:
    """A ``[signals]`` table for the quantities ``measured`` as the contract carries them.

    Built from ``monitor.wire.telemetry.SAMPLE_FIELDS`` and the contract's command, so the live default map,
    identify's aircraft map and the vehicle's encoder cannot disagree on a message, a field or a scale.

    >>> print(contract_signals_toml(["alpha", "elevator"], ["alpha"], ranges=False))  # doctest: +NORMALIZE_WHITESPACE
    [signals]
    instant = "AOA_SSA"
    outputs = ["alpha"]
    actuator = ["elevator"]
    [signals.measured]
    alpha = { field = "AOA_SSA.AOA", unit = "deg" }
    elevator = { field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }
    [signals.command]
    message = "SET_ACTUATOR_CONTROL_TARGET"
    channels = [1]
    full_scale = [30.0]
    group = 0
    """
    lines = ["[signals]", f"instant = {json.dumps(INSTANT_MESSAGE)}"]
    if outputs is not None:
        lines.append(f"outputs = {json.dumps(list(outputs))}")
    lines += [f"actuator = {json.dumps(list(actuator))}", "[signals.measured]"]
    for name in measured:
        f = field_of(name)
        parts = [f"field = {json.dumps(f.ref)}"]
        if f.scale != 1.0:
            parts.append(f"scale = {f.scale!r}")
        parts.append(f"unit = {json.dumps(f.unit)}")
        if ranges:
            parts.append(f"range = [{f.range[0]!r}, {f.range[1]!r}]")
        lines.append(f"{name} = {{ {', '.join(parts)} }}")
    lines += [
        "[signals.command]",
        'message = "SET_ACTUATOR_CONTROL_TARGET"',
        f"channels = [{PITCH_CHANNEL}]",
        f"full_scale = [{ELEVATOR_FULL_SCALE_DEG!r}]",
        "group = 0",
    ]
    return "\n".join(lines) + "\n"


# what the monitor reads from a vehicle when the plant file has no [signals]: the linear plant's sample
DEFAULT_SIGNALS_TOML = contract_signals_toml(["alpha", "q", "elevator"], outputs=["alpha"])

_TOP_KEYS = {"instant", "outputs", "actuator", "record", "measured", "command", "operating_point", "condition"}
_SIGNAL_KEYS = {"field", "scale", "offset", "unit", "range", "hold"}
_INPUT_KEYS = {"field", "scale", "offset", "hold"}  # an input of a derived signal
DEFAULT_HOLD_S = 1.0  # a latest-value signal (no time field) older than this, in the vehicle's seconds, is not used
_COMMAND_KEYS = {"message", "channels", "full_scale", "group"}
_COMMAND_MESSAGES = {"SET_ACTUATOR_CONTROL_TARGET": ("controls", 8)}


@dataclass(frozen=True)
class Signal:
    """One measured value: ``scale * message.field[index] + offset`` in ``unit``."""

    name: str
    message: str
    field: str
    index: int
    position: int  # flat position in the message's unpacked payload
    scale: float
    unit: str
    offset: float = 0.0
    range: tuple[float, float] | None = None  # the physical envelope, plant units (None: any finite value)
    hold: float | None = None  # None: matched by its message's time field; else a latest value, usable this long (s)
    derivation: Derivation | None = None  # a derived signal (monitor.link.derived): computed from its inputs

    @property
    def timed(self) -> bool:
        return self.hold is None


@dataclass(frozen=True)
class CommandMap:
    message: str
    channels: tuple[int, ...]
    full_scale: tuple[float, ...]
    group: int


@dataclass(frozen=True)
class SignalMap:
    """A validated signal map for a plant with ``l`` outputs and ``m`` inputs."""

    instant: str
    measured: dict[str, Signal]
    outputs: tuple[str, ...]
    actuator: tuple[str, ...]
    record: tuple[str, ...]
    command: CommandMap
    time_fields: dict[str, tuple[int, int, int]]  # timed message -> (flat position of its time field, us per unit,
    #                                              units after which it wraps: 2^32 for a 32-bit field, else 0)
    source: str
    operating_point: dict[str, float] | None = None  # plant units, every output and actuator signal (None: zero)
    y0: tuple[float, ...] = ()  # the operating point of the outputs, in the order of ``outputs`` (zeros if none)
    u0: tuple[float, ...] = ()  # ... and of the actuator signals
    # the other measured signals where the model was identified (bank, yaw rate): the flight condition that an
    # envelope can be scheduled on besides the operating point (None: not stated)
    condition: dict[str, float] | None = None
    # the derived signals' inputs (``alpha.velocity_ned[0]``), read from messages like the measured signals
    inputs: dict[str, Signal] = dc_field(default_factory=dict)

    def __post_init__(self) -> None:
        op = self.operating_point or {}
        if len(self.y0) != len(self.outputs):
            object.__setattr__(self, "y0", tuple(float(op.get(n, 0.0)) for n in self.outputs))
        if len(self.u0) != len(self.actuator):
            object.__setattr__(self, "u0", tuple(float(op.get(n, 0.0)) for n in self.actuator))
        raw = {n: s for n, s in self.measured.items() if s.derivation is None}
        object.__setattr__(self, "raw", {**raw, **self.inputs})
        derived = tuple((n, s.derivation) for n, s in self.measured.items() if s.derivation is not None)
        object.__setattr__(self, "derived", derived)
        ranges = {n: sig.range for n, sig in self.measured.items()}
        judged = tuple((n, ranges.get(n)) for n in (*self.outputs, *self.actuator))
        object.__setattr__(self, "judged", judged)

    # every signal read from a message (the measured ones and the derived signals' inputs), by name: what the
    # assembler joins; and the derived signals, computed from those once a sample is complete
    raw: dict[str, Signal] = dc_field(init=False, repr=False, compare=False)
    derived: tuple[tuple[str, Derivation], ...] = dc_field(init=False, repr=False, compare=False)
    # what ``reject_reason`` judges, per sample: (signal, its range or None) of the outputs and actuator signals
    judged: tuple[tuple[str, tuple[float, float] | None], ...] = dc_field(init=False, repr=False, compare=False)

    def read_from(self, names) -> tuple[str, ...]:
        """The signals read from messages that ``names`` need: themselves, or a derived signal's inputs."""
        out: list[str] = []
        for name in names:
            d = self.measured[name].derivation
            out.extend(d.inputs if d is not None else (name,))
        return tuple(dict.fromkeys(out))

    def messages_of(self, name: str) -> tuple[str, ...]:
        """The messages a measured signal is read from (a derived signal: its inputs')."""
        return tuple(dict.fromkeys(self.raw[n].message for n in self.read_from((name,))))

    def complete_derived(self, values: dict[str, float]) -> None:
        """A complete sample's derived signals computed from its inputs (those present), the inputs dropped."""
        for name, derivation in self.derived:
            inputs = derivation.inputs
            if all(n in values for n in inputs):
                values[name] = derivation.compute(values)
            for n in inputs:
                values.pop(n, None)

    def deviations(
        self, values: dict[str, float], y0: Sequence[float] | None = None, u0: Sequence[float] | None = None
    ) -> tuple[list[float], list[float] | None]:
        """``y - y0`` and ``u - u0`` (None when the sample has no complete actuator report) for the estimator; the
        map's own operating point unless a trim is given (an envelope's, interpolated between its points)."""
        y = [values[name] - y0 for name, y0 in zip(self.outputs, self.y0 if y0 is None else y0, strict=True)]
        u_trim = self.u0 if u0 is None else u0
        report = [values[name] - u0 for name, u0 in zip(self.actuator, u_trim, strict=True) if name in values]
        return y, (report if len(report) == len(self.actuator) else None)

    def absolute(self, u, u0: Sequence[float] | None = None) -> list[float]:
        """A command in deviation coordinates as the absolute deflection that goes on the wire, ``u0 + u``."""
        return [trim + float(v) for trim, v in zip(self.u0 if u0 is None else u0, u, strict=True)]

    def describe_operating_point(self) -> str | None:
        """``operating point alpha 2.31 deg, ..., elevator -4.3 deg`` (None when the map has none)."""
        if self.operating_point is None:
            return None
        parts = []
        for name in (*self.outputs, *self.actuator):
            unit = self.measured[name].unit
            parts.append(f"{name} {self.operating_point[name]:.6g}" + (f" {unit}" if unit else ""))
        return "operating point " + ", ".join(parts)

    def messages(self, observe: bool) -> tuple[str, ...]:
        """Every message whose parts make one sample (the instant first): what the estimator cannot do without."""
        names = [self.instant] + [m for s in self.outputs for m in self.messages_of(s)]  # incl. latest values
        if observe:
            names += [m for s in self.actuator for m in self.messages_of(s)]
        return tuple(dict.fromkeys(names))

    def reject_reason(self, values: dict[str, float]) -> str | None:
        """Why a sample's values cannot go to the estimator (non-finite or outside a signal's range), or None.

        Only the signals the estimator uses are judged; a bad recorded-only signal is dropped by the caller.
        """
        for name, bounds in self.judged:
            v = values.get(name)
            if v is None:
                continue
            if not math.isfinite(v):
                return f"{name} = {v}"
            if bounds is not None and not bounds[0] <= v <= bounds[1]:
                return f"{name} = {v:.6g} outside [{bounds[0]:g}, {bounds[1]:g}]"
        return None

    def actuator_messages(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(m for s in self.actuator for m in self.messages_of(s)))

    def describe(self) -> str:
        def where(sig: Signal) -> str:
            if sig.derivation is not None:
                return sig.derivation.describe()
            return f"{sig.message}.{sig.field}" + ("" if sig.timed else " (latest value)")

        outs = ", ".join(f"y{i}={where(self.measured[s])}" for i, s in enumerate(self.outputs))
        return f"instant {self.instant}; {outs}"


def _field_ref(text: Any, where: str, layouts: Layouts) -> tuple[MessageLayout, str, int]:
    if not isinstance(text, str) or "." not in text:
        raise UserError(f"{where}: expected 'MESSAGE.field' or 'MESSAGE.field[index]', got {text!r}")
    message, _, rest = text.partition(".")
    layout = layouts(message)
    if layout is None:
        raise UserError(f"{where}: {layouts.unknown(message)}")
    field, index = rest, 0
    if rest.endswith("]") and "[" in rest:
        field, _, idx = rest[:-1].rpartition("[")
        if not idx.isdigit():
            raise UserError(f"{where}: bad index in '{text}'")
        index = int(idx)
    try:
        layout.position(field, index)
    except ValueError as exc:
        raise UserError(f"{where}: {exc}") from None
    return layout, field, index


def _range(bounds: Any, w: str) -> tuple[float, float] | None:
    if bounds is None:
        return None
    if (
        not isinstance(bounds, list)
        or len(bounds) != 2
        or not all(isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b) for b in bounds)
        or not bounds[0] < bounds[1]
    ):
        raise UserError(f"{w}: 'range' must be [low, high] with finite low < high")
    return (float(bounds[0]), float(bounds[1]))


def _read_signal(
    name: str, spec: Any, w: str, layouts: Layouts, time_fields: dict[str, tuple[int, int, int]]
) -> Signal:
    """One value read from one field: ``scale * MESSAGE.field[index] + offset`` (its message's time field noted in
    ``time_fields``); ``spec`` a field reference or a table of field, scale, offset, unit, range, hold."""
    if not isinstance(spec, dict):
        spec = {"field": spec}
    layout, field, index = _field_ref(spec.get("field"), w, layouts)
    scale = spec.get("scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale == 0:
        raise UserError(f"{w}: 'scale' must be a finite non-zero number")
    offset = spec.get("offset", 0.0)
    if isinstance(offset, bool) or not isinstance(offset, (int, float)) or not math.isfinite(offset):
        raise UserError(f"{w}: 'offset' must be a finite number")
    stamp = layout.time_field()
    hold = spec.get("hold")
    if stamp is not None:
        time_fields[layout.name] = (layout.position(stamp[0]), stamp[1], layout.wrap(stamp[0]))
    elif hold is None:  # no time field (VFR_HUD): a latest value, sample and hold
        hold = DEFAULT_HOLD_S
    if hold is not None:  # a latest value: stamped by its own time field if it has one (a slower topic)
        if isinstance(hold, bool) or not isinstance(hold, (int, float)) or not (math.isfinite(hold) and hold > 0):
            raise UserError(f"{w}: 'hold' must be a positive number of seconds")
        hold = float(hold)
    return Signal(
        name,
        layout.name,
        field,
        index,
        layout.position(field, index),
        float(scale),
        str(spec.get("unit", "")),
        float(offset),
        _range(spec.get("range"), w),
        hold,
    )


def _names(
    raw: dict, key: str, where: str, measured: dict[str, Signal], default: list | None = None
) -> tuple[str, ...]:
    value = raw.get(key, default)
    if value is None:
        raise UserError(f"{where}: missing key '{key}'")
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise UserError(f"{where}: '{key}' must be a list of signal names")
    for name in value:
        if name not in measured:
            raise UserError(f"{where}: '{key}' names '{name}', which is not in [signals.measured]")
    return tuple(value)


def _number_list(value: Any, n: int, where: str, key: str, kind: type) -> tuple:
    if not isinstance(value, list):
        value = [value]
    if len(value) != n or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise UserError(f"{where}: '{key}' must be a list of {n} number(s), one per plant input")
    return tuple(kind(v) for v in value)


def parse_signals(raw: Any, source: str, outputs: int, inputs: int, layouts: Layouts = MAVLINK) -> SignalMap:
    """Validate a ``[signals]`` table for a plant with ``outputs`` rows of C and ``inputs`` inputs (names looked up
    in ``layouts``: the MAVLink dialect, or a DataFlash log's own messages)."""
    where = f"{source}: [signals]"
    if not isinstance(raw, dict):
        raise UserError(f"{where}: must be a table")
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise UserError(f"{where}: unknown key '{unknown[0]}' (known: {', '.join(sorted(_TOP_KEYS))})")
    measured: dict[str, Signal] = {}
    time_fields: dict[str, tuple[int, int, int]] = {}
    table = raw.get("measured")
    if not isinstance(table, dict) or not table:
        raise UserError(f"{where}: needs a [signals.measured] table of name = {{ field = ... }}")
    hidden_inputs: dict[str, Signal] = {}

    def read_input(hidden: str, spec: Any, w: str) -> None:
        """A derived signal's input: a field reference or a table of field, scale, offset, hold."""
        if hidden in table:
            raise UserError(f"{w}: the name '{hidden}' is taken by the derivation's input: rename the signal")
        bad = sorted(set(spec) - _INPUT_KEYS) if isinstance(spec, dict) else []
        if bad:
            raise UserError(f"{w}: unknown key '{bad[0]}' (an input takes: field, scale, offset, hold)")
        hidden_inputs[hidden] = _read_signal(hidden, spec, w, layouts, time_fields)

    for name, spec in table.items():
        w = f"{where} measured.{name}"
        if isinstance(spec, dict) and "derive" in spec:
            try:
                derivation, unit = parse_derivation(name, spec, w, read_input)
            except ValueError as exc:
                raise UserError(str(exc)) from None
            first = hidden_inputs[derivation.inputs[0]]
            timed = all(hidden_inputs[n].timed for n in derivation.inputs)
            holds = [hidden_inputs[n].hold for n in derivation.inputs if hidden_inputs[n].hold is not None]
            measured[name] = Signal(
                name,
                first.message,
                derivation.kind,
                0,
                -1,
                1.0,
                unit,
                0.0,
                _range(spec.get("range"), w),
                None if timed else min(h for h in holds if h is not None),
                derivation,
            )
            continue
        if isinstance(spec, dict):
            bad = sorted(set(spec) - _SIGNAL_KEYS)
            if bad:
                raise UserError(f"{w}: unknown key '{bad[0]}' (known: field, scale, offset, unit, range, hold, derive)")
        measured[name] = _read_signal(name, spec, w, layouts, time_fields)
    instant = raw.get("instant")
    instant_layout = layouts(instant) if isinstance(instant, str) else None
    if instant_layout is None:
        raise UserError(f"{where}: 'instant' must name a {layouts.kind} message, got {instant!r}")
    stamp = instant_layout.time_field()
    if stamp is None or stamp[0] != layouts.instant_field:
        raise UserError(f"{where}: the instant message {instant_layout.name} needs a {layouts.instant_field} field")
    time_fields[instant_layout.name] = (instant_layout.position(stamp[0]), 1, instant_layout.wrap(stamp[0]))
    outs = _names(raw, "outputs", where, measured)
    if len(outs) != outputs:
        raise UserError(
            f"{where}: 'outputs' names {len(outs)} signal(s) but the plant has {outputs} output(s) (rows of C)"
        )
    act = _names(raw, "actuator", where, measured)
    if len(act) != inputs:
        raise UserError(f"{where}: 'actuator' names {len(act)} signal(s) but the plant has {inputs} input(s)")
    for name in act:
        if not measured[name].timed:
            why = (
                "'hold' makes it a latest value"
                if name in time_fields or measured[name].message in time_fields
                else f"{measured[name].message} has no time_usec or time_boot_ms"
            )
            raise UserError(
                f"{where}: actuator '{name}': {why}, and the actuator report must be matched to its instant"
            )
    op = _operating_point(raw.get("operating_point"), where, measured, outs, act)
    condition = _condition(raw.get("condition"), where, measured, (*outs, *act))
    record = _names(raw, "record", where, measured, default=list(measured))
    cmd = raw.get("command", {})
    if not isinstance(cmd, dict):
        raise UserError(f"{where}: 'command' must be a table")
    bad = sorted(set(cmd) - _COMMAND_KEYS)
    if bad:
        raise UserError(f"{where} command: unknown key '{bad[0]}' (known: {', '.join(sorted(_COMMAND_KEYS))})")
    message = str(cmd.get("message", "SET_ACTUATOR_CONTROL_TARGET")).upper()
    if message not in _COMMAND_MESSAGES:
        raise UserError(f"{where} command: message '{message}' is not supported (use SET_ACTUATOR_CONTROL_TARGET)")
    width = _COMMAND_MESSAGES[message][1]
    channels = _number_list(cmd.get("channels", [1] * inputs), inputs, f"{where} command", "channels", int)
    if any(not 0 <= ch < width for ch in channels):
        raise UserError(f"{where} command: channels must be in 0..{width - 1}")
    full_scale = _number_list(cmd.get("full_scale", [30.0] * inputs), inputs, f"{where} command", "full_scale", float)
    if any(not (math.isfinite(s) and s > 0) for s in full_scale):
        raise UserError(f"{where} command: full_scale must be positive")
    group = cmd.get("group", 0)
    if isinstance(group, bool) or not isinstance(group, int) or not 0 <= group <= 255:
        raise UserError(f"{where} command: group must be an integer 0-255")
    return SignalMap(
        instant_layout.name,
        measured,
        outs,
        act,
        record,
        CommandMap(message, channels, full_scale, group),
        time_fields,
        source,
        op,
        condition=condition,
        inputs=hidden_inputs,
    )


def _operating_point(
    raw: Any, where: str, measured: dict[str, Signal], outs: tuple[str, ...], act: tuple[str, ...]
) -> dict[str, float] | None:
    """``operating_point = { name = value, ... }``: every output and actuator signal, each a finite number."""
    if raw is None:
        return None
    w = f"{where} operating_point"
    if not isinstance(raw, dict):
        raise UserError(f"{w}: must be a table {{ name = value, ... }} naming every output and actuator signal")
    wanted = (*outs, *act)
    for name in raw:
        if name not in measured:
            raise UserError(f"{w}: names '{name}', which is not in [signals.measured]")
        if name not in wanted:
            raise UserError(
                f"{w}: names '{name}', which is not an output or actuator signal (give: {', '.join(wanted)})"
            )
    missing = [name for name in wanted if name not in raw]
    if missing:
        raise UserError(
            f"{w}: missing {', '.join(repr(n) for n in missing)} (it must name every output and "
            f"actuator signal: {', '.join(wanted)})"
        )
    op: dict[str, float] = {}
    for name in wanted:
        value = raw[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise UserError(f"{w}: '{name}' must be a finite number (plant units), got {value!r}")
        bounds = measured[name].range
        if bounds is not None and not bounds[0] <= value <= bounds[1]:
            raise UserError(f"{w}: '{name}' = {value:g} is outside its range [{bounds[0]:g}, {bounds[1]:g}]")
        op[name] = float(value)
    return op


def _condition(raw: Any, where: str, measured: dict[str, Signal], own: tuple[str, ...]) -> dict[str, float] | None:
    """``condition = { roll = 45.0, r = 12.1 }``: measured signals other than the outputs and the actuator (those are
    the operating point's), each a finite number in its unit: where the model was identified."""
    if raw is None:
        return None
    w = f"{where} condition"
    if not isinstance(raw, dict):
        raise UserError(f"{w}: must be a table {{ name = value, ... }} of measured signals")
    condition: dict[str, float] = {}
    for name, value in raw.items():
        if name not in measured:
            raise UserError(f"{w}: names '{name}', which is not in [signals.measured]")
        if name in own:
            raise UserError(f"{w}: names '{name}', an output or actuator signal: its trim is in operating_point")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise UserError(f"{w}: '{name}' must be a finite number, got {value!r}")
        condition[name] = float(value)
    return condition


def default_signal_map(outputs: int = 1, inputs: int = 1) -> SignalMap:
    """The contract's mapping (alpha, q, elevator) for the paper's aircraft."""
    return parse_signals(tomllib.loads(DEFAULT_SIGNALS_TOML)["signals"], "default signal map", outputs, inputs)


def load_signals_file(path: str | Path, outputs: int, inputs: int, layouts: Layouts = MAVLINK) -> SignalMap:
    """A TOML file holding a ``[signals]`` table (a plant file with one works too)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text("utf-8"))
    except FileNotFoundError:
        raise UserError(f"{path}: signal map file not found") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"{path}: cannot read signal map: {exc}") from None
    if "signals" not in raw:
        raise UserError(f"{path}: no [signals] table")
    return parse_signals(raw["signals"], str(path), outputs, inputs, layouts)


def signals_for_plant(plant, signals_file: str | Path | None = None, layouts: Layouts = MAVLINK) -> SignalMap:
    """``--signals FILE`` if given, else the plant file's own ``[signals]`` table, else the default."""
    if signals_file is not None:
        return load_signals_file(signals_file, plant.l, plant.m, layouts)
    raw = getattr(plant, "signals", None)
    if raw is not None:
        return parse_signals(raw, plant.name, plant.l, plant.m, layouts)
    reason = layouts.no_map()
    if reason is not None:
        raise UserError(f"plant {plant.name} has no [signals] table: {reason}")
    if plant.l != 1 or plant.m != 1:
        raise UserError(
            f"plant {plant.name}: has {plant.l} output(s) and {plant.m} input(s); the default signal map "
            "is for 1 and 1 (alpha, elevator): give a [signals] table or --signals FILE"
        )
    return default_signal_map()
