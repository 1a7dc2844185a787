"""A c172p flown by JSBSim in process, logged as PX4 logs a fixed-wing (a ULog of PX4's topics) and as a
MAVLink autopilot streams one (a tlog of ATTITUDE, LOCAL_POSITION_NED, WIND_COV, ACTUATOR_OUTPUT_STATUS): what
the derived angle of attack is read from, with JSBSim's own α beside it to compare.

The flight: c172p trimmed by JSBSim (``tests/c172p_flights.trimmed_c172p``), integrated at 200 Hz, sampled at
50 Hz (h = 0.02 s); a lead-in of trimmed flight, then an elevator PRBS about trim. A steady wind set after the
trim (JSBSim's trim zeroes it) and JSBSim's MIL-spec turbulence are optional. Per sample: JSBSim's ``aero/alpha-deg``,
``aero/beta-deg``, ``velocities/u-aero-fps``, true and calibrated airspeed, the NED velocity, the Euler angles,
the body rates, the total wind (steady + turbulence, NED) and the elevator: its normalised command (PX4's
``actuator_servos.control``, c172p: +1 is 23 deg trailing edge down, -1 is 28 deg up) and the surface (deg).

The ULog (``write_px4_ulog``) has PX4's topic and field names (msg/*.msg) and the rates of PX4's logger with
the high-rate profile (``SDLOG_PROFILE`` bit 2: ``vehicle_angular_velocity``, ``vehicle_attitude``,
``actuator_servos`` at full rate, here 50 Hz) and ``vehicle_local_position`` at full rate (a
``logger_topics.txt`` line, ``vehicle_local_position 0``: its default 10 Hz would hold the velocity 100 ms),
``airspeed_validated`` at 5 Hz and ``wind`` at 1 Hz (their defaults), ``actuator_outputs`` (the servo PWM,
instances 0 and 1) at 10 Hz. Each topic is stamped a little after the sample's instant, in the order PX4's
modules publish within a cycle, with up to 1 ms of jitter.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tests.c172p_flights import prbs, quiet, trimmed_c172p

H = 0.02
STEPS_PER_SAMPLE = 4  # 200 Hz
T0_US = 123_456_000  # PX4's boot clock at the first sample (whole ms: MAVLink's time_boot_ms carries it exactly)
FT = 0.3048
KT = 1852.0 / 3600.0
THROW = (-28.0, 23.0)  # c172p's elevator (deg) at command -1 and +1


@dataclass
class Px4Flight:
    """Per sample k (instant ``t_us[k]``): JSBSim's truth and what PX4 would log."""

    t_us: np.ndarray
    alpha: np.ndarray  # deg, aero/alpha-deg
    beta: np.ndarray  # deg, aero/beta-deg
    u_aero: np.ndarray  # m/s, velocities/u-aero-fps
    tas: np.ndarray  # m/s
    cas: np.ndarray  # m/s
    v_ned: np.ndarray  # (n, 3) m/s
    euler: np.ndarray  # (n, 3) rad: roll, pitch, yaw
    rates: np.ndarray  # (n, 3) rad/s: p, q, r
    wind: np.ndarray  # (n, 3) m/s NED, steady + turbulence
    control: np.ndarray  # the elevator's normalised command over [k, k+1)
    elevator: np.ndarray  # deg, the surface over [k, k+1)
    trim_elevator: float

    def __len__(self) -> int:
        return len(self.t_us)


def fly(
    seconds: float,
    lead_in: float = 3.0,
    amplitude: float = 1.0,
    seed: int = 0,
    airspeed_kt: float = 90.0,
    altitude_ft: float = 4000.0,
    wind_ned_fps: tuple[float, float, float] = (0.0, 0.0, 0.0),
    turbulence: str | None = None,
    bias_deg: float = 0.0,
    fault_at_s: float | None = None,
) -> Px4Flight:
    """``bias_deg`` from ``fault_at_s`` (s after the first sample): an elevator fault, the surface that much off
    the deflection commanded (the logged control stays the command; ``elevator`` is the surface)."""
    fdm = trimmed_c172p(airspeed_kt, altitude_ft, dt=H / STEPS_PER_SAMPLE)
    total = fdm["fcs/elevator-cmd-norm"] + fdm["fcs/pitch-trim-cmd-norm"]
    trim_deg = fdm["fcs/elevator-pos-deg"]
    fdm["fcs/pitch-trim-cmd-norm"] = 0.0  # the trim moves into the command: the surface stays put
    fdm["fcs/elevator-cmd-norm"] = total
    for axis, value in zip(("north", "east", "down"), wind_ned_fps, strict=True):
        fdm[f"atmosphere/wind-{axis}-fps"] = value
    if turbulence is not None:
        from monitor.wire import TURBULENCE_INTENSITY
        from sim_vehicle.jsbsim_model import MILSPEC

        windspeed_fps, severity = TURBULENCE_INTENSITY[turbulence]
        fdm["atmosphere/turb-type"] = MILSPEC
        fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = windspeed_fps
        fdm["atmosphere/turbulence/milspec/severity"] = severity
    if any(wind_ned_fps) or turbulence is not None:
        with quiet():
            fdm.run()  # JSBSim reports the total wind once it has run a step with it
    lead, main = round(lead_in / H), round(seconds / H)
    du = np.concatenate([np.zeros(lead), prbs(main, amplitude, seed, h=H)])
    n = len(du)
    g = fdm.get_property_value
    cols = np.empty((n, 20))
    with quiet():
        for k, d in enumerate(du):
            deflection = trim_deg + d
            command = _command(deflection)
            faulty = fault_at_s is not None and k * H >= fault_at_s
            cols[k, :18] = (
                g("aero/alpha-deg"),
                g("aero/beta-deg"),
                g("velocities/u-aero-fps") * FT,
                g("velocities/vt-fps") * FT,
                g("velocities/vc-kts") * KT,
                g("velocities/v-north-fps") * FT,
                g("velocities/v-east-fps") * FT,
                g("velocities/v-down-fps") * FT,
                g("attitude/phi-rad"),
                g("attitude/theta-rad"),
                g("attitude/psi-rad"),
                g("velocities/p-rad_sec"),
                g("velocities/q-rad_sec"),
                g("velocities/r-rad_sec"),
                g("atmosphere/total-wind-north-fps") * FT,
                g("atmosphere/total-wind-east-fps") * FT,
                g("atmosphere/total-wind-down-fps") * FT,
                command,
            )
            fdm["fcs/elevator-cmd-norm"] = _command(deflection + bias_deg) if faulty else command
            fdm.run()
            cols[k, 18] = g("fcs/elevator-pos-deg")  # the surface over this sample (the FCS has no lag)
            for _ in range(STEPS_PER_SAMPLE - 1):
                fdm.run()
    t_us = T0_US + np.arange(n, dtype=np.int64) * round(H * 1e6)
    c = cols.T
    return Px4Flight(
        t_us,
        c[0],
        c[1],
        c[2],
        c[3],
        c[4],
        cols[:, 5:8],
        cols[:, 8:11],
        cols[:, 11:14],
        cols[:, 14:17],
        c[17],
        c[18],
        float(trim_deg),
    )


def _command(deflection: float) -> float:
    """The c172p's normalised elevator command for a deflection (deg), through its unequal throws."""
    return deflection / (THROW[1] if deflection >= 0 else -THROW[0])


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """[w, x, y, z] rotating body axes into NED (ZYX Euler angles), as PX4's vehicle_attitude.q."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


PX4_TOPICS: dict[str, list[tuple[str, str]]] = {
    "vehicle_angular_velocity": [
        ("uint64_t", "timestamp"),
        ("uint64_t", "timestamp_sample"),
        ("float[3]", "xyz"),
        ("float[3]", "xyz_derivative"),
    ],
    "vehicle_attitude": [
        ("uint64_t", "timestamp"),
        ("uint64_t", "timestamp_sample"),
        ("float[4]", "q"),
        ("float[4]", "delta_q_reset"),
        ("uint8_t", "quat_reset_counter"),
    ],
    "vehicle_local_position": [
        ("uint64_t", "timestamp"),
        ("uint64_t", "timestamp_sample"),
        *(("float", f) for f in ("x", "y", "z", "vx", "vy", "vz", "heading")),
    ],
    "airspeed_validated": [
        ("uint64_t", "timestamp"),
        *(("float", f) for f in ("indicated_airspeed_m_s", "calibrated_airspeed_m_s", "true_airspeed_m_s")),
    ],
    "wind": [
        ("uint64_t", "timestamp"),
        ("uint64_t", "timestamp_sample"),
        *(("float", f) for f in ("windspeed_north", "windspeed_east", "variance_north", "variance_east")),
    ],
    "actuator_servos": [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("float[15]", "control")],
    "actuator_outputs": [("uint64_t", "timestamp"), ("uint32_t", "noutputs"), ("float[16]", "output")],
}
# (topic, every how many samples with the high-rate profile, every how many with PX4's default logging, the
# sample the default's subsampling starts at, publication delay after the instant in us): PX4's order in a cycle
_SCHEDULE = (
    ("vehicle_angular_velocity", 1, 1, 0, 150),
    ("vehicle_attitude", 1, 2, 1, 300),
    ("vehicle_local_position", 1, 5, 2, 450),
    ("actuator_servos", 1, 5, 0, 700),
    ("actuator_outputs", 5, 5, 0, 800),
    ("airspeed_validated", 10, 10, 3, 600),
    ("wind", 50, 50, 0, 900),
)


def write_px4_ulog(path: Path, flight: Px4Flight, seed: int = 0, default_rates: bool = False) -> None:
    """The flight as PX4's logger writes it (see the module docstring): rates, topics, stamps. ``default_rates``:
    PX4's default logging instead (``vehicle_attitude`` 25 Hz here, ``vehicle_local_position`` and
    ``actuator_servos`` 10 Hz, out of phase: the logger takes each topic's newest at its own interval)."""
    from tests.ulog_writer import ULogWriter

    rng = np.random.default_rng(seed)
    records: list[tuple[int, str, int, list]] = []
    position = np.cumsum(flight.v_ned * H, axis=0)
    for k in range(len(flight)):
        t = int(flight.t_us[k])
        roll, pitch, yaw = flight.euler[k]
        servo = [0.0] * 15
        servo[1] = float(flight.control[k])  # the elevator: servo 2 of a PX4 plane (index 1)
        for topic, every_high, every_default, phase, delay in _SCHEDULE:
            every = every_default if default_rates else every_high
            if (k - (phase if default_rates else 0)) % every:
                continue
            stamp = t + delay + int(rng.integers(0, 1000))
            if topic == "vehicle_angular_velocity":
                values = [stamp, t, *flight.rates[k], 0.0, 0.0, 0.0]
            elif topic == "vehicle_attitude":
                values = [stamp, t, *quaternion(roll, pitch, yaw), 0.0, 0.0, 0.0, 0.0, 0]
            elif topic == "vehicle_local_position":
                values = [stamp, t, *position[k], *flight.v_ned[k], yaw]
            elif topic == "airspeed_validated":
                values = [stamp, flight.cas[k], flight.cas[k], flight.tas[k]]
            elif topic == "wind":
                values = [stamp, t, flight.wind[k, 0], flight.wind[k, 1], 0.1, 0.1]
            elif topic == "actuator_servos":
                values = [stamp, t, *servo]
            else:  # actuator_outputs: PWM 1000-2000 us, MAIN (instance 0) and AUX (instance 1)
                pwm = [1500.0 + 500.0 * s for s in servo] + [0.0]
                records.append((stamp + 1, topic, 1, [stamp + 1, 8, *([1500.0] * 8 + [0.0] * 8)]))
                values = [stamp, 8, *pwm]
            records.append((stamp, topic, 0, values))
    records.sort(key=lambda r: r[0])
    info = {
        "sys_name": "PX4",
        "ver_hw": "JSBSIM_C172P",
        "sys_vehicle_type": "fixed-wing (written by tests/px4_flight.py)",
    }
    with ULogWriter(path, int(flight.t_us[0]) - 2_000_000, PX4_TOPICS, info) as log:
        for topic in PX4_TOPICS:
            log.subscribe(topic)
        log.subscribe("actuator_outputs", 1)
        for _stamp, topic, multi_id, values in records:
            log.write(topic, values, multi_id)


def mavlink_samples(flight: Px4Flight, sysid: int = 1) -> Iterator[tuple[int, list[bytes]]]:
    """Per sample: its instant (us since boot) and the frames a MAVLink autopilot without an AoA vane sends:
    ATTITUDE (rad), LOCAL_POSITION_NED (m/s), WIND_COV (the wind, NED m/s) and ACTUATOR_OUTPUT_STATUS (the
    elevator's normalised command in actuator[1]), each stamped with the sample's instant."""
    from monitor.wire.mavlink import mavlink, new_codec

    codec = new_codec(sysid, 1)
    for k in range(len(flight)):
        t = int(flight.t_us[k])
        msgs = [
            mavlink.MAVLink_attitude_message(t // 1000, *map(float, flight.euler[k]), *map(float, flight.rates[k])),
            mavlink.MAVLink_local_position_ned_message(t // 1000, 0.0, 0.0, 0.0, *map(float, flight.v_ned[k])),
            mavlink.MAVLink_wind_cov_message(t, *map(float, flight.wind[k]), 0.0, 0.0, 0.0, 0.0, 0.0),
            mavlink.MAVLink_actuator_output_status_message(t, 2, [0.0, float(flight.control[k])] + [0.0] * 30),
        ]
        frames = []
        for msg in msgs:
            codec.send(msg)
            frames.append(codec.file.take())
        yield t, frames


def write_mavlink_tlog(path: Path, flight: Px4Flight, sysid: int = 1) -> None:
    """``mavlink_samples`` as MAVProxy logs them: one frame per record, 0.5 ms apart."""
    stamp = struct.Struct(">Q")
    with open(path, "wb") as fh:
        for t, frames in mavlink_samples(flight, sysid):
            for i, frame in enumerate(frames):
                fh.write(stamp.pack(1_700_000_000_000_000 + t + i * 500) + frame)
