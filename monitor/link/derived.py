"""Derived signals: a value computed from several fields by a built-in derivation that names its inputs.

Why: what the plant needs is often not a field the autopilot sends. PX4 logs and streams no angle of attack
(``vehicle_attitude``'s quaternion and ``vehicle_local_position``'s NED velocity are there, and α is
``atan2(w_b, u_b)`` of the air-relative velocity in body axes); many ArduPilot airframes have no vane; an
elevator is reported as a normalised control in [-1, 1] or a servo PWM with unequal throws up and down. A
signal map says so in ``[signals.measured]``::

    alpha = { derive = "angle_of_attack", unit = "deg",
              velocity_ned = ["vehicle_local_position.vx", "vehicle_local_position.vy", "vehicle_local_position.vz"],
              attitude_quaternion = ["vehicle_attitude.q[0]", "vehicle_attitude.q[1]", "vehicle_attitude.q[2]",
                                     "vehicle_attitude.q[3]"],
              wind_ne = ["wind.windspeed_north", "wind.windspeed_east"] }          # optional
    elevator = { derive = "pwm", input = "SERVO_OUTPUT_RAW.servo2_raw", pwm = [1100, 1500, 1900],
                 throw = [-28.0, 23.0], unit = "deg" }

The grammar is data, never code: a derivation is one of ``DERIVATIONS`` (no expression of user text is
evaluated), each with its own keys, each input a field reference (``"MSG.field[i]"``) or a table
``{ field, scale, offset, hold }`` read exactly as a measured signal is (the same lookup, time matching and
``hold``). Unknown derivations, keys, missing or surplus inputs, a wrong count are one-line errors naming them.

The inputs become hidden signals of the map (``alpha.velocity_ned[0]``...) that the ``SampleAssembler`` joins
like any other (so the derivation works the same live, in tlogs, DataFlash and ULog logs); when a sample is
complete the derived value is computed from them and the hidden values are dropped. A derivation whose result
is undefined (a zero airspeed) gives NaN, which the estimator's input check rejects.

Conventions: NED velocities and wind (m/s), wind the velocity of the air (where it blows to, as PX4's ``wind``
topic and ArduPilot's ``NKF2.VWN``); an attitude quaternion ``[w, x, y, z]`` rotating body axes into NED (PX4's
``vehicle_attitude.q``, MAVLink's ``ATTITUDE_QUATERNION``); Euler angles ``[roll, pitch, yaw]`` in radians
(ZYX, MAVLink's ``ATTITUDE``; give ``scale`` on each input to convert degrees); body velocities ``[u, v, w]``
already relative to the air. α = atan2(w_b, u_b), β = asin(v_b / V).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["DERIVATIONS", "Derivation", "parse_derivation"]

# role -> (number of fields, what they are)
_ROLES: dict[str, tuple[int, str]] = {
    "velocity_ned": (3, "north, east, down"),
    "velocity_body": (3, "u, v, w (relative to the air)"),
    "attitude_quaternion": (4, "w, x, y, z"),
    "attitude_euler": (3, "roll, pitch, yaw in rad"),
    "wind_ned": (3, "north, east, down"),
    "wind_ne": (2, "north, east"),
    "input": (1, "one field"),
}
_COMMON_KEYS = ("derive", "unit", "range")
_ANGLE_UNITS = {"deg": 180.0 / math.pi, "rad": 1.0}


@dataclass(frozen=True)
class _Kind:
    """One derivation: the keys it takes besides the common ones, and what it computes."""

    roles: tuple[str, ...]  # the input roles it may take
    params: tuple[str, ...]  # its numeric keys
    unit: str  # the default unit of its result
    about: str


DERIVATIONS: dict[str, _Kind] = {
    "angle_of_attack": _Kind(
        ("velocity_ned", "velocity_body", "attitude_quaternion", "attitude_euler", "wind_ned", "wind_ne"),
        (),
        "deg",
        "atan2(w_b, u_b) of the air-relative velocity in body axes",
    ),
    "sideslip": _Kind(
        ("velocity_ned", "velocity_body", "attitude_quaternion", "attitude_euler", "wind_ned", "wind_ne"),
        (),
        "deg",
        "asin(v_b / V) of the air-relative velocity in body axes",
    ),
    "airspeed": _Kind(
        ("velocity_ned", "velocity_body", "wind_ned", "wind_ne"), (), "m/s", "the norm of the air-relative velocity"
    ),
    "roll": _Kind(("attitude_quaternion",), (), "deg", "the ZYX Euler roll of the attitude quaternion"),
    "pitch": _Kind(("attitude_quaternion",), (), "deg", "the ZYX Euler pitch of the attitude quaternion"),
    "yaw": _Kind(("attitude_quaternion",), (), "deg", "the ZYX Euler yaw of the attitude quaternion"),
    "control": _Kind(("input",), ("throw",), "deg", "a normalised control in [-1, 1] times its throw"),
    "pwm": _Kind(("input",), ("pwm", "throw"), "deg", "a servo PWM about its trim, through its throws"),
    "degrees": _Kind(("input",), (), "deg", "radians to degrees"),
    "radians": _Kind(("input",), (), "rad", "degrees to radians"),
}


@dataclass(frozen=True)
class Derivation:
    """A parsed derivation: its kind, its inputs (hidden signal names, role by role) and its parameters."""

    kind: str
    roles: tuple[tuple[str, tuple[str, ...]], ...]  # (role, hidden input names) in the order given
    params: tuple[float, ...] = ()
    to_unit: float = 1.0  # the result's factor from the derivation's natural unit (rad -> deg)

    @property
    def inputs(self) -> tuple[str, ...]:
        return tuple(n for _role, names in self.roles for n in names)

    def describe(self) -> str:
        """``angle_of_attack(velocity_ned, attitude_quaternion)``: for reports and errors."""
        return f"{self.kind}({', '.join(role for role, _ in self.roles)})"

    def compute(self, values: dict[str, float]) -> float:
        """The derived value from the sample's input values (every input present)."""
        got = {role: [values[n] for n in names] for role, names in self.roles}
        if self.kind in ("control", "pwm", "degrees", "radians"):
            return self.to_unit * _scalar(self.kind, got["input"][0], self.params)
        if self.kind in _EULER:
            return self.to_unit * _euler(self.kind, got["attitude_quaternion"])
        u, v, w = _air_body(got)
        if self.kind == "airspeed":
            return math.sqrt(u * u + v * v + w * w)
        if self.kind == "angle_of_attack":
            return self.to_unit * math.atan2(w, u) if (u or w) else math.nan
        speed = math.sqrt(u * u + v * v + w * w)
        return self.to_unit * math.asin(max(-1.0, min(1.0, v / speed))) if speed > 0 else math.nan


_EULER = ("roll", "pitch", "yaw")


def _euler(kind: str, q: list[float]) -> float:
    """A ZYX Euler angle (rad) of the quaternion [w, x, y, z] (body to NED), as PX4's Eulerf(Quatf) gives it."""
    norm = math.sqrt(sum(c * c for c in q)) or 1.0
    w, x, y, z = (c / norm for c in q)
    if kind == "roll":
        return math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    if kind == "pitch":
        return math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def _scalar(kind: str, x: float, params: tuple[float, ...]) -> float:
    if kind == "degrees":
        return math.degrees(x)
    if kind == "radians":
        return math.radians(x)
    if kind == "control":  # throw at -1, throw at +1
        low, high = params
        return x * high if x >= 0 else -x * low
    pmin, trim, pmax, low, high = params  # pwm: value at pmin is low, at trim 0, at pmax high
    return (x - trim) / (pmax - trim) * high if x >= trim else (trim - x) / (trim - pmin) * low


def _air_body(got: dict[str, list[float]]) -> tuple[float, float, float]:
    """The air-relative velocity in body axes: given, or the NED velocity less the wind rotated into the body."""
    if "velocity_body" in got:
        u, v, w = got["velocity_body"]
        return u, v, w
    n, e, d = got["velocity_ned"]
    wind = got.get("wind_ned") or [*got.get("wind_ne", [0.0, 0.0]), 0.0]
    n, e, d = n - wind[0], e - wind[1], d - wind[2]
    if "attitude_quaternion" not in got and "attitude_euler" not in got:  # an airspeed: the norm needs no axes
        return n, e, d
    r = _body_to_ned(got)
    # body = R^T ned
    return (
        r[0][0] * n + r[1][0] * e + r[2][0] * d,
        r[0][1] * n + r[1][1] * e + r[2][1] * d,
        r[0][2] * n + r[1][2] * e + r[2][2] * d,
    )


def _body_to_ned(got: dict[str, list[float]]) -> tuple[tuple[float, float, float], ...]:
    """The rotation matrix body -> NED from the quaternion (normalised) or the ZYX Euler angles."""
    if "attitude_quaternion" in got:
        qw, qx, qy, qz = got["attitude_quaternion"]
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz) or 1.0
        qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
        return (
            (1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)),
            (2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)),
            (2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)),
        )
    roll, pitch, yaw = got["attitude_euler"]
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    return (
        (cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy),
        (cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy),
        (-sp, sr * cp, cr * cp),
    )


def _one_of(spec: dict, choices: tuple[str, ...], w: str, required: bool) -> str | None:
    given = [r for r in choices if r in spec]
    if len(given) > 1:
        raise ValueError(f"{w}: give one of {', '.join(choices)}, not {' and '.join(given)}")
    if required and not given:
        raise ValueError(f"{w}: needs {' or '.join(choices)}")
    return given[0] if given else None


def _numbers(value: Any, n: int, w: str, key: str) -> tuple[float, ...]:
    if not isinstance(value, list):
        value = [value]
    if len(value) != n or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        raise ValueError(f"{w}: '{key}' must be {n} finite number(s)")
    return tuple(float(v) for v in value)


def _throw(spec: dict, w: str) -> tuple[float, float]:
    """``throw = 25`` (-25 at the low end, +25 at the high end) or ``throw = [at low, at high]``."""
    if "throw" not in spec:
        raise ValueError(f"{w}: needs 'throw' (plant units at full deflection: a number, or [at low, at high])")
    raw = spec["throw"]
    if isinstance(raw, list):
        low, high = _numbers(raw, 2, w, "throw")
    else:
        (high,) = _numbers(raw, 1, w, "throw")
        low = -high
    if low == 0 and high == 0:
        raise ValueError(f"{w}: 'throw' must not be zero")
    return low, high


def parse_derivation(
    name: str, spec: dict, w: str, parse_input: Callable[[str, Any, str], None]
) -> tuple[Derivation, str]:
    """Check a derived signal's table and register its inputs (``parse_input(hidden name, field spec, where)``, the
    map's own field reader); returns the derivation and its unit. ValueError (one line) on anything wrong."""
    raw_kind = spec.get("derive")
    kind = DERIVATIONS.get(raw_kind) if isinstance(raw_kind, str) else None
    if kind is None or not isinstance(raw_kind, str):
        raise ValueError(f"{w}: unknown derivation {raw_kind!r} (known: {', '.join(DERIVATIONS)})")
    kind_name: str = raw_kind
    known = (*_COMMON_KEYS, *kind.roles, *kind.params)
    bad = [k for k in spec if k not in known]
    if bad:
        raise ValueError(f"{w}: '{kind_name}' takes no key '{bad[0]}' (its keys: {', '.join(known)})")
    if len(kind.roles) == 1:
        chosen = [_one_of(spec, kind.roles, w, True)]
    else:
        velocity = _one_of(spec, ("velocity_ned", "velocity_body"), w, True)
        attitude = _one_of(spec, ("attitude_quaternion", "attitude_euler"), w, False)
        wind = _one_of(spec, ("wind_ned", "wind_ne"), w, False)
        if velocity == "velocity_body" and (attitude or wind):
            raise ValueError(f"{w}: velocity_body is already relative to the air in body axes: drop {attitude or wind}")
        if velocity == "velocity_ned" and attitude is None and kind_name != "airspeed":
            raise ValueError(f"{w}: velocity_ned needs attitude_quaternion or attitude_euler to reach body axes")
        chosen = [r for r in (velocity, attitude, wind) if r is not None]
    roles = []
    for role in chosen:
        assert role is not None
        count, what = _ROLES[role]
        refs = spec[role]
        if count == 1:
            refs = [refs]
        if not isinstance(refs, list) or len(refs) != count:
            raise ValueError(f"{w}: '{role}' needs {count} fields ({what})")
        hidden = tuple(f"{name}.{role}" + (f"[{i}]" if count > 1 else "") for i in range(count))
        for hidden_name, ref in zip(hidden, refs, strict=True):
            parse_input(hidden_name, ref, f"{w} {hidden_name.partition('.')[2]}")
        roles.append((role, hidden))
    params: tuple[float, ...] = ()
    if kind_name == "control":
        params = _throw(spec, w)
    elif kind_name == "pwm":
        pwm = _numbers(spec.get("pwm"), 3, w, "pwm")
        if not pwm[0] < pwm[1] < pwm[2]:
            raise ValueError(f"{w}: 'pwm' must be [min, trim, max] with min < trim < max")
        params = (*pwm, *_throw(spec, w))
    unit = spec.get("unit", kind.unit)
    if not isinstance(unit, str):
        raise ValueError(f"{w}: 'unit' must be a string")
    to_unit = 1.0
    if kind_name in ("angle_of_attack", "sideslip", *_EULER):
        if unit not in _ANGLE_UNITS:
            raise ValueError(f"{w}: an angle's 'unit' is deg or rad, got {unit!r}")
        to_unit = _ANGLE_UNITS[unit]
    return Derivation(kind_name, tuple(roles), params, to_unit), unit
