"""A fast path for the monitor's own traffic: the three telemetry frames in, the command frame out.

Why: pymavlink's parser is a pure-Python state machine plus a generic decoder that builds a
message object per frame; it was ~60% of the monitor's per-sample time (benchmarks/bench_monitor.py).
A vehicle's datagram is almost always exactly ATTITUDE + AOA_SSA + ACTUATOR_OUTPUT_STATUS, unsigned
MAVLink 2, so ``split_telemetry`` checks that shape with ``struct`` and the same CRC (``fastcrc``, with
each message's CRC extra) and unpacks only the fields the monitor reads. Anything else (signed or v1
frames, other ids, bad prefix/CRC/length, trailing bytes) returns None and the caller uses pymavlink,
which keeps every reject counted exactly as before. ``encode_command`` packs the reply with the bytes
pymavlink would produce (tests/test_wire_fastframe.py compares them) for unsigned links only.
"""

from __future__ import annotations

import struct

from monitor.wire.mavlink import (
    ELEVATOR_FULL_SCALE_DEG,
    PITCH_CHANNEL,
    VEHICLE_COMPONENT,
    Command,
    mavlink,
    sample_instant_us,
)

__all__ = ["ATTITUDE", "AOA_SSA", "ACTUATOR", "Frame", "split_telemetry", "encode_command"]

try:
    from fastcrc.crc16 import mcrf4xx as _crc16
except ImportError:  # pymavlink's own (slower, same result)
    def _crc16(data, initial: int | None = None) -> int:
        crc = mavlink.x25crc()
        if initial is not None:
            crc.crc = initial
        crc.accumulate(bytes(data))
        return crc.crc

ATTITUDE = mavlink.MAVLINK_MSG_ID_ATTITUDE
AOA_SSA = mavlink.MAVLINK_MSG_ID_AOA_SSA
ACTUATOR = mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS
_STX = mavlink.PROTOCOL_MARKER_V2
_HEADER = 10  # MAVLink 2 header: magic .. msgid (3 bytes)
_OVERHEAD = _HEADER + 2  # + CRC

# (msgid, sysid, instant, value): ATTITUDE (time_boot_ms, pitchspeed rad/s), AOA_SSA (time_usec, AOA deg),
# ACTUATOR_OUTPUT_STATUS (time_usec, actuator[0] deg)
Frame = tuple[int, int, int, float]

# msgid -> (CRC extra as bytes, struct of the leading fields up to the one we read)
_SPECS: dict[int, tuple[bytes, struct.Struct]] = {
    ATTITUDE: (bytes((mavlink.MAVLink_attitude_message.crc_extra,)), struct.Struct("<I16xf")),
    AOA_SSA: (bytes((mavlink.MAVLink_aoa_ssa_message.crc_extra,)), struct.Struct("<Qf")),
    ACTUATOR: (bytes((mavlink.MAVLink_actuator_output_status_message.crc_extra,)), struct.Struct("<Q4xf")),
}


def split_telemetry(data: bytes) -> list[Frame] | None:
    """The datagram's frames if all are good unsigned v2 telemetry frames, else None (use pymavlink)."""
    frames: list[Frame] = []
    i, n = 0, len(data)
    while i < n:
        if n - i < _OVERHEAD or data[i] != _STX or data[i + 2]:  # short, not v2, or signed/unknown flags
            return None
        mlen = data[i + 1]
        end = i + _OVERHEAD + mlen
        msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
        spec = _SPECS.get(msgid)
        if end > n or spec is None:
            return None
        extra, fields = spec
        if _crc16(extra, _crc16(data[i + 1 : end - 2])) != data[end - 2] | data[end - 1] << 8:
            return None
        start = i + _HEADER
        if mlen >= fields.size:
            instant, value = fields.unpack_from(data, start)
        else:  # MAVLink 2 strips trailing zero bytes: put them back
            instant, value = fields.unpack(data[start : start + mlen] + bytes(fields.size - mlen))
        frames.append((msgid, data[i + 5], instant, value))
        i = end
    return frames


_CMD = mavlink.MAVLink_set_actuator_control_target_message
_CMD_HEADER = struct.Struct("<BBBBBBBHB")
_CMD_EXTRA = bytes((_CMD.crc_extra,))
_CRC = struct.Struct("<H")
_ZERO_CONTROLS = (0.0,) * 8


def encode_command(mav: mavlink.MAVLink, command: Command, h: float) -> bytes:
    """``monitor.wire.mavlink.encode_command`` for an unsigned codec, byte for byte, without pymavlink objects."""
    if mav.signing.sign_outgoing:
        raise ValueError("fastframe.encode_command is for unsigned links; use monitor.wire.mavlink.encode_command")
    controls = list(_ZERO_CONTROLS)
    controls[PITCH_CHANNEL] = float(command.elevator_deg) / ELEVATOR_FULL_SCALE_DEG
    payload = _CMD.unpacker.pack(sample_instant_us(command.k, h), *controls, 0, command.sysid, VEHICLE_COMPONENT)
    payload = payload.rstrip(b"\x00") or payload[:1]  # MAVLink 2 payload truncation, at least one byte
    seq = mav.seq
    frame = _CMD_HEADER.pack(_STX, len(payload), 0, 0, seq, mav.srcSystem, mav.srcComponent, _CMD.id & 0xFFFF,
                             _CMD.id >> 16) + payload
    frame += _CRC.pack(_crc16(_CMD_EXTRA, _crc16(frame[1:])))
    mav.seq = (seq + 1) % 256
    mav.total_packets_sent += 1
    mav.total_bytes_sent += len(frame)
    return frame
