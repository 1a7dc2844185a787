"""The MAVLink side of the contract, shared by the vehicle and the monitor so both agree on units.

Vehicle -> monitor, each sample k (one datagram): its messages and fields are defined once, in
``monitor.wire.telemetry`` (``SAMPLE_FIELDS``), which also encodes them; this module holds the codec and the
instants.
Monitor -> vehicle: ``SET_ACTUATOR_CONTROL_TARGET`` with ``time_usec`` = the sampling instant it answers,
group 0, ``controls[1]`` (the pitch channel) = elevator command / ``ELEVATOR_FULL_SCALE_DEG``
(MAVLink controls are normalised to [-1, 1]). Plant units are degrees and deg/s; the wire uses MAVLink's.

Why a bare ``MAVLink`` object instead of ``mavutil``: mavutil flips process-wide dialect state and owns
the socket; the daemons own their asyncio sockets and need one parser per peer.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = [
    "mavlink",
    "ELEVATOR_FULL_SCALE_DEG",
    "PITCH_CHANNEL",
    "Command",
    "new_codec",
    "FrameSink",
    "enable_signing",
    "encode_command",
    "encode_heartbeat",
    "sample_instant_us",
    "sample_index",
    "command_elevator_deg",
    "bump_signing_clock",
    "MONITOR_COMPONENT",
    "VEHICLE_COMPONENT",
]

ELEVATOR_FULL_SCALE_DEG = 30.0
PITCH_CHANNEL = 1
MONITOR_COMPONENT = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
VEHICLE_COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1


@dataclass(frozen=True)
class Command:
    """An elevator command that answers sample k."""

    sysid: int
    k: int
    elevator_deg: float


class FrameSink:
    """A file-like target that keeps the last encoded frame (the codec never owns a socket)."""

    def __init__(self) -> None:
        self.buffer = bytearray()

    def write(self, data: bytes) -> None:
        self.buffer += data

    def take(self) -> bytes:
        out = bytes(self.buffer)
        self.buffer.clear()
        return out


def new_codec(sysid: int, component: int) -> mavlink.MAVLink:
    """A MAVLink 2 encoder/decoder for one peer, with robust parsing on.

    Robust parsing turns garbage and bad CRCs into ``BAD_DATA`` messages instead of raising once and
    then stalling (which would lose later good frames).
    """
    mav = mavlink.MAVLink(FrameSink(), srcSystem=sysid, srcComponent=component)
    mav.robust_parsing = True
    return mav


def enable_signing(mav: mavlink.MAVLink, key: bytes, link_id: int = 0, sign_outgoing: bool = True) -> None:
    """Sign outgoing frames and reject unsigned or wrongly signed incoming ones (32-byte key)."""
    if len(key) != 32:
        raise ValueError(f"MAVLink signing key must be 32 bytes, got {len(key)}")
    mav.signing.secret_key = key
    mav.signing.link_id = link_id
    mav.signing.sign_outgoing = sign_outgoing
    mav.signing.allow_unsigned_callback = None
    bump_signing_clock(mav)


def bump_signing_clock(mav: mavlink.MAVLink) -> None:
    """Keep the signing timestamp at wall-clock time (10 us units since 2015-01-01).

    pymavlink only adds 1 per frame, so a long run falls behind and a restarted peer rejects it.
    """
    import time

    now = int((time.time() - 1420070400) * 100000)
    if now > mav.signing.timestamp:
        mav.signing.timestamp = now


def sample_instant_us(k: int, h: float) -> int:
    return int(round(k * h * 1e6))


def sample_index(time_usec: int, h: float) -> int:
    return int(round(time_usec / (h * 1e6)))


def encode_command(mav: mavlink.MAVLink, command: Command, h: float) -> bytes:
    controls = [0.0] * 8
    controls[PITCH_CHANNEL] = float(command.elevator_deg) / ELEVATOR_FULL_SCALE_DEG
    msg = mavlink.MAVLink_set_actuator_control_target_message(
        sample_instant_us(command.k, h), 0, command.sysid, VEHICLE_COMPONENT, controls
    )
    mav.send(msg)
    return mav.file.take()


def encode_heartbeat(mav: mavlink.MAVLink, vehicle: bool = True) -> bytes:
    kind = mavlink.MAV_TYPE_FIXED_WING if vehicle else mavlink.MAV_TYPE_ONBOARD_CONTROLLER
    autopilot = mavlink.MAV_AUTOPILOT_GENERIC if vehicle else mavlink.MAV_AUTOPILOT_INVALID
    mav.send(mavlink.MAVLink_heartbeat_message(kind, autopilot, 0, 0, mavlink.MAV_STATE_ACTIVE, 3))
    return mav.file.take()


def command_elevator_deg(msg) -> float:
    """Elevator (degrees) carried by a ``SET_ACTUATOR_CONTROL_TARGET`` message."""
    return float(msg.controls[PITCH_CHANNEL]) * ELEVATOR_FULL_SCALE_DEG
