"""What the monitor sends: the command, its feedback to ground stations, and its heartbeat.

Contract: ``SET_ACTUATOR_CONTROL_TARGET`` with ``time_usec`` = the instant it answers and
``controls[channel]`` = u / full_scale; ``NAMED_VALUE_FLOAT`` ``FHAT`` (``FHAT0``, ``FHAT1``... with
several fault channels) with ``time_boot_ms`` = the instant, every processed sample; ``STATUSTEXT``
WARNING on alarm raise and INFO on clear; ``HEARTBEAT`` at 1 Hz (an onboard controller, so routers learn
the way back). Every frame comes from the link's ``FrameEncoder``: its sequence numbers and signing.
"""

from __future__ import annotations

import math

from monitor.link.dialect import known_layout, mavlink
from monitor.link.frames import FrameEncoder
from monitor.link.signals import CommandMap

__all__ = [
    "MONITOR_SYSID",
    "MONITOR_COMPONENT",
    "VEHICLE_COMPONENT",
    "command_frame",
    "fhat_frames",
    "alarm_text_frame",
    "heartbeat_frame",
    "fhat_name",
]

MONITOR_SYSID = 255  # a ground-station id, as MAVProxy uses; vehicles are 1-254
MONITOR_COMPONENT = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
VEHICLE_COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1

_COMMAND = known_layout("SET_ACTUATOR_CONTROL_TARGET")
_NAMED_FLOAT = known_layout("NAMED_VALUE_FLOAT")
_STATUSTEXT = known_layout("STATUSTEXT")
_HEARTBEAT = known_layout("HEARTBEAT")
_FLOAT32_MAX = 3.4028234663852886e38


def _f32(value) -> float:
    """A value MAVLink's float32 can carry: beyond its range, the infinity of the same sign (never a crash)."""
    v = float(value)
    return v if -_FLOAT32_MAX <= v <= _FLOAT32_MAX or v != v else math.copysign(math.inf, v)


_HEARTBEAT_VALUES = (
    0,
    mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
    mavlink.MAV_AUTOPILOT_INVALID,
    0,
    mavlink.MAV_STATE_ACTIVE,
    3,
)


def command_frame(enc: FrameEncoder, cmd: CommandMap, sysid: int, time_usec: int, u) -> bytes:
    """The command for ``sysid`` answering the instant ``time_usec``; ``u`` in plant units, already saturated."""
    controls = [0.0] * 8
    for channel, scale, value in zip(cmd.channels, cmd.full_scale, u, strict=True):
        v = float(value) / scale
        controls[channel] = v if -_FLOAT32_MAX <= v <= _FLOAT32_MAX or v != v else math.copysign(math.inf, v)
    return enc.encode(_COMMAND, (time_usec, *controls, cmd.group, sysid, VEHICLE_COMPONENT))


def fhat_name(index: int, channels: int) -> bytes:
    return b"FHAT" if channels == 1 else f"FHAT{index}".encode()


def fhat_frames(enc: FrameEncoder, time_usec: int, f_hat) -> bytes:
    """One ``NAMED_VALUE_FLOAT`` per fault channel, concatenated (one datagram)."""
    ms = (time_usec // 1000) & 0xFFFFFFFF
    n = len(f_hat)
    if n == 1:  # the common case, without the join
        return enc.encode(_NAMED_FLOAT, (ms, _f32(f_hat[0]), b"FHAT"))
    return b"".join(enc.encode(_NAMED_FLOAT, (ms, _f32(v), fhat_name(i, n))) for i, v in enumerate(f_hat))


def alarm_text_frame(enc: FrameEncoder, sysid: int, state: str, magnitude: float, unit: str) -> bytes:
    """``STATUSTEXT``: WARNING when the alarm is raised, INFO when it clears (50 characters at most)."""
    severity = mavlink.MAV_SEVERITY_WARNING if state == "raised" else mavlink.MAV_SEVERITY_INFO
    text = f"sysid {sysid} fault alarm {state} |fhat| {magnitude:.3g} {unit}"[:50]
    return enc.encode(_STATUSTEXT, (severity, text.encode(), 0, 0))


def heartbeat_frame(enc: FrameEncoder) -> bytes:
    return enc.encode(_HEARTBEAT, _HEARTBEAT_VALUES)
