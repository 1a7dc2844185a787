"""The aircraft's telemetry per sample: the contract's messages with a full attitude, plus VFR_HUD.

The linear plant's samples keep ``monitor.wire.mavlink.encode_sample`` (ATTITUDE with pitch rate only,
AOA_SSA, ACTUATOR_OUTPUT_STATUS). An aircraft has more to say, in the same single datagram per sample:
``ATTITUDE`` (roll, pitch = theta, yaw in rad; body rates in rad/s; ``time_boot_ms`` = k h),
``AOA_SSA`` (alpha in degrees, ``time_usec`` = k h), ``VFR_HUD`` (airspeed and groundspeed m/s, heading deg,
throttle %, altitude m, climb m/s; it has no time field, so it travels with the sample's other messages)
and ``ACTUATOR_OUTPUT_STATUS`` (actuator[0] = the absolute elevator deflection in degrees, trim included).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from monitor.wire.mavlink import Sample, mavlink, sample_instant_us

__all__ = ["AircraftSample", "encode_aircraft_sample"]


@dataclass(frozen=True)
class AircraftSample(Sample):
    """A ``Sample`` with what a full aircraft model measures besides alpha, q and the elevator."""

    theta_deg: float = 0.0
    airspeed_m_s: float = 0.0
    attitude: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # roll, yaw (rad), p, r (rad/s)
    # groundspeed (m/s), heading (deg), throttle (%), altitude (m), climb (m/s)
    hud: tuple[float, float, int, float, float] = (0.0, 0.0, 0, 0.0, 0.0)


def encode_aircraft_sample(mav: mavlink.MAVLink, sample: AircraftSample, h: float) -> bytes:
    """ATTITUDE, AOA_SSA, VFR_HUD and ACTUATOR_OUTPUT_STATUS of one sample, concatenated into one datagram."""
    t_us = sample_instant_us(sample.k, h)
    roll, yaw, p, r = sample.attitude
    groundspeed, heading, throttle, alt, climb = sample.hud
    frames = [
        mavlink.MAVLink_attitude_message(int(t_us // 1000) & 0xFFFFFFFF, float(roll),
                                         math.radians(sample.theta_deg), float(yaw), float(p),
                                         math.radians(sample.q_deg_s), float(r)),
        mavlink.MAVLink_aoa_ssa_message(t_us, float(sample.alpha_deg), 0.0),
        mavlink.MAVLink_vfr_hud_message(float(sample.airspeed_m_s), float(groundspeed), int(round(heading)) % 360,
                                        max(0, min(100, int(throttle))), float(alt), float(climb)),
        mavlink.MAVLink_actuator_output_status_message(t_us, 1, [float(sample.elevator_deg)] + [0.0] * 31),
    ]
    for msg in frames:
        mav.send(msg)
    return mav.file.take()
