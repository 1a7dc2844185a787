"""What one telemetry sample is made of on the wire: the one definition of its MAVLink messages and fields.

Every side of the link is built from ``SAMPLE_FIELDS``: the vehicle's encoder (``encode_sample``), the
monitor's default signal map and identify's aircraft map (``monitor.link.signals.contract_signals_toml``), and
the in-process flights' reader (``wire_values``). Why one table: the same fact written four times (encoder,
live map, identify's map, the Monte Carlo's reader) drifted one copy at a time; a quantity added here reaches
all of them, and a test encodes a sample and decodes it through the link layer.

Each sample k is one datagram (loss and reordering act on whole samples). Quantities are in plant units
(degrees, deg/s, m/s); each row says how the wire carries one: ``wire value * scale = plant value``. The
linear plant reports alpha, q and the elevator (``Sample``); an aircraft adds its attitude, body rates and
VFR_HUD (``AircraftSample``), and, flown by its own autopilot (``sim-vehicle --mission``), the autopilot's part of
the elevator and the compensation received from outside in ``actuator[1]`` and ``actuator[2]`` (``actuator[0]``
stays the whole deflection applied). The sample's instant is ``AOA_SSA.time_usec`` (k h in microseconds);
``ATTITUDE.time_boot_ms`` and ``ACTUATOR_OUTPUT_STATUS.time_usec`` carry the same instant; ``VFR_HUD`` has no
time field and travels in the same datagram.

>>> [f.name for f in SAMPLE_FIELDS if f.message == "ATTITUDE"]
['q', 'theta', 'roll', 'yaw', 'p', 'r']
>>> field_of("elevator").ref
'ACTUATOR_OUTPUT_STATUS.actuator[0]'
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from monitor.wire.mavlink import mavlink, sample_instant_us

__all__ = [
    "SampleField",
    "SAMPLE_FIELDS",
    "INSTANT_MESSAGE",
    "Sample",
    "AircraftSample",
    "field_of",
    "quantities",
    "wire_values",
    "encode_sample",
]

DEG_PER_RAD = 180.0 / math.pi  # the scale a signal map writes for a radian field read in degrees


@dataclass(frozen=True)
class SampleField:
    """One quantity of a sample and where the wire carries it."""

    name: str  # the name signal maps use ("alpha")
    message: str  # MAVLink message ("AOA_SSA")
    field: str  # its field ("AOA")
    index: int | None  # element of an array field, None for a scalar
    scale: float  # wire value * scale = plant value
    unit: str  # plant unit
    range: tuple[float, float]  # a plausible plant value: outside it, a sample is rejected as corrupt

    @property
    def ref(self) -> str:
        """The field as a signal map names it: ``MESSAGE.field`` or ``MESSAGE.field[i]``."""
        return f"{self.message}.{self.field}" + ("" if self.index is None else f"[{self.index}]")


SAMPLE_FIELDS: tuple[SampleField, ...] = (
    SampleField("alpha", "AOA_SSA", "AOA", None, 1.0, "deg", (-90.0, 90.0)),
    SampleField("q", "ATTITUDE", "pitchspeed", None, DEG_PER_RAD, "deg/s", (-2000.0, 2000.0)),
    SampleField("theta", "ATTITUDE", "pitch", None, DEG_PER_RAD, "deg", (-180.0, 180.0)),
    SampleField("roll", "ATTITUDE", "roll", None, DEG_PER_RAD, "deg", (-180.0, 180.0)),
    SampleField("yaw", "ATTITUDE", "yaw", None, DEG_PER_RAD, "deg", (-360.0, 360.0)),
    SampleField("p", "ATTITUDE", "rollspeed", None, DEG_PER_RAD, "deg/s", (-2000.0, 2000.0)),
    SampleField("r", "ATTITUDE", "yawspeed", None, DEG_PER_RAD, "deg/s", (-2000.0, 2000.0)),
    SampleField("airspeed", "VFR_HUD", "airspeed", None, 1.0, "m/s", (0.0, 400.0)),
    SampleField("groundspeed", "VFR_HUD", "groundspeed", None, 1.0, "m/s", (0.0, 400.0)),
    SampleField("heading", "VFR_HUD", "heading", None, 1.0, "deg", (0.0, 360.0)),
    SampleField("throttle", "VFR_HUD", "throttle", None, 1.0, "%", (0.0, 100.0)),
    SampleField("altitude", "VFR_HUD", "alt", None, 1.0, "m", (-500.0, 20000.0)),
    SampleField("climb", "VFR_HUD", "climb", None, 1.0, "m/s", (-100.0, 100.0)),
    SampleField("elevator", "ACTUATOR_OUTPUT_STATUS", "actuator", 0, 1.0, "deg", (-90.0, 90.0)),
    # an aircraft flown by its own autopilot (sim-vehicle --mission): the two parts of the elevator in actuator[0]
    SampleField("autopilot_elevator", "ACTUATOR_OUTPUT_STATUS", "actuator", 1, 1.0, "deg", (-90.0, 90.0)),
    SampleField("compensation", "ACTUATOR_OUTPUT_STATUS", "actuator", 2, 1.0, "deg", (-90.0, 90.0)),
)
INSTANT_MESSAGE = "AOA_SSA"  # the message whose time field defines sample k
_MESSAGE_ORDER = ("ATTITUDE", "AOA_SSA", "VFR_HUD", "ACTUATOR_OUTPUT_STATUS")  # in the datagram
_BY_NAME = {f.name: f for f in SAMPLE_FIELDS}


def field_of(name: str) -> SampleField:
    """The definition of quantity ``name`` (a ``KeyError`` naming the known ones otherwise)."""
    try:
        return _BY_NAME[name]
    except KeyError:
        raise KeyError(f"no sample quantity '{name}' (known: {', '.join(_BY_NAME)})") from None


@dataclass(frozen=True)
class Sample:
    """What the vehicle reports at sampling instant k (plant units): the linear plant's quantities."""

    sysid: int
    k: int
    t: float  # sampling instant, seconds of simulated time
    alpha_deg: float
    q_deg_s: float
    elevator_deg: float


@dataclass(frozen=True)
class AircraftSample(Sample):
    """A ``Sample`` with what a full aircraft model measures besides alpha, q and the elevator."""

    theta_deg: float = 0.0
    airspeed_m_s: float = 0.0
    attitude: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # roll, yaw (rad), p, r (rad/s)
    # groundspeed (m/s), heading (deg), throttle (%), altitude (m), climb (m/s)
    hud: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    # flown by its own autopilot (a mission): its own elevator and the compensation received, whose sum (clipped to
    # the travel) is elevator_deg; 0 when nobody flies on board
    autopilot_elevator: float = 0.0
    compensation: float = 0.0


def quantities(sample: Sample) -> dict[str, float]:
    """The sample's quantities by ``SAMPLE_FIELDS`` name, in plant units (only those this kind of sample has)."""
    values = {"alpha": sample.alpha_deg, "q": sample.q_deg_s, "elevator": sample.elevator_deg}
    if isinstance(sample, AircraftSample):
        roll, yaw, p, r = sample.attitude
        groundspeed, heading, throttle, altitude, climb = sample.hud
        values.update(
            theta=sample.theta_deg,
            roll=math.degrees(roll),
            yaw=math.degrees(yaw),
            p=math.degrees(p),
            r=math.degrees(r),
            airspeed=sample.airspeed_m_s,
            groundspeed=groundspeed,
            heading=heading,
            throttle=throttle,
            altitude=altitude,
            climb=climb,
            autopilot_elevator=sample.autopilot_elevator,
            compensation=sample.compensation,
        )
    return values


def wire_values(sample: Sample) -> dict[tuple[str, str, int | None], float]:
    """What the wire carries for each field of the sample, ``(message, field, index) -> value`` in wire units."""
    values = {}
    for name, value in quantities(sample).items():
        f = _BY_NAME[name]
        values[(f.message, f.field, f.index)] = value / f.scale
    return values


def _message(name: str, fields: dict[str, float], elements: dict[str, dict[int, float]], t_us: int):
    """One message of the sample: its defined fields set, its time field at the sample's instant, the rest 0."""
    if name == "ATTITUDE":
        return mavlink.MAVLink_attitude_message(
            int(t_us // 1000) & 0xFFFFFFFF,
            *(float(fields.get(f, 0.0)) for f in ("roll", "pitch", "yaw", "rollspeed", "pitchspeed", "yawspeed")),
        )
    if name == "AOA_SSA":
        return mavlink.MAVLink_aoa_ssa_message(t_us, float(fields.get("AOA", 0.0)), 0.0)
    if name == "VFR_HUD":
        return mavlink.MAVLink_vfr_hud_message(
            float(fields.get("airspeed", 0.0)),
            float(fields.get("groundspeed", 0.0)),
            int(round(fields.get("heading", 0.0))) % 360,
            max(0, min(100, int(fields.get("throttle", 0.0)))),
            float(fields.get("alt", 0.0)),
            float(fields.get("climb", 0.0)),
        )
    if name == "ACTUATOR_OUTPUT_STATUS":
        actuator = [0.0] * 32
        active = 0  # the bitmask of the outputs the sample fills
        for index, value in elements.get("actuator", {}).items():
            actuator[index] = float(value)
            active |= 1 << index
        return mavlink.MAVLink_actuator_output_status_message(t_us, active, actuator)
    raise ValueError(f"no encoder for message {name}")  # pragma: no cover - SAMPLE_FIELDS names only the above


def encode_sample(mav: mavlink.MAVLink, sample: Sample, h: float) -> bytes:
    """The messages of one sample, concatenated into one datagram (the messages its quantities need)."""
    t_us = sample_instant_us(sample.k, h)
    per_message: dict[str, tuple[dict[str, float], dict[str, dict[int, float]]]] = {}
    for (message, field, index), value in wire_values(sample).items():
        scalars, arrays = per_message.setdefault(message, ({}, {}))
        if index is None:
            scalars[field] = value
        else:
            arrays.setdefault(field, {})[index] = value
    for name in _MESSAGE_ORDER:
        if name in per_message:
            mav.send(_message(name, *per_message[name], t_us))
    return mav.file.take()
