"""The telemetry/command fast path agrees with pymavlink, and declines whatever it does not vouch for."""

from __future__ import annotations

import math

import pytest

from monitor.wire import fastframe
from monitor.wire.mavlink import (
    MONITOR_COMPONENT, VEHICLE_COMPONENT, Command, Sample, enable_signing, encode_command, encode_heartbeat,
    encode_sample, new_codec,
)

CASES = [(0, 0.0, 0.0, 0.0), (1, 0.5, 1.0, 0.25), (7, -3.25, -12.5, 0.0), (123456, 1e-3, 0.0, -7.5),
         (2**20, 0.0, 3.0, 0.0)]


@pytest.mark.parametrize("k, alpha, q, elev", CASES)
def test_split_matches_pymavlink(k: int, alpha: float, q: float, elev: float) -> None:
    data = encode_sample(new_codec(9, VEHICLE_COMPONENT), Sample(9, k, k * 0.02, alpha, q, elev), 0.02)
    msgs = new_codec(255, MONITOR_COMPONENT).parse_buffer(data)
    att, aoa, act = msgs
    assert fastframe.split_telemetry(data) == [
        (fastframe.ATTITUDE, 9, att.time_boot_ms, att.pitchspeed),
        (fastframe.AOA_SSA, 9, aoa.time_usec, aoa.AOA),
        (fastframe.ACTUATOR, 9, act.time_usec, act.actuator[0]),
    ]


def test_split_declines_anything_unusual() -> None:
    vehicle = new_codec(1, VEHICLE_COMPONENT)
    good = encode_sample(vehicle, Sample(1, 5, 5.0, 0.5, 1.0, 0.25), 1.0)
    bad_crc = bytearray(good)
    bad_crc[20] ^= 0xFF
    signed = new_codec(1, VEHICLE_COMPONENT)
    enable_signing(signed, bytes(range(32)))
    for data in (b"", good[:-1], good + b"\x00", bytes(bad_crc), b"garbage" + good, encode_heartbeat(vehicle),
                 encode_sample(signed, Sample(1, 5, 5.0, 0.5, 1.0, 0.25), 1.0)):
        if data:
            assert fastframe.split_telemetry(data) is None
    assert fastframe.split_telemetry(b"") == []


@pytest.mark.parametrize("k, elev", [(0, 0.0), (1, 1.5), (99, -30.0), (2**33, 1e-7), (5, math.pi)])
def test_encode_command_is_byte_for_byte_pymavlink(k: int, elev: float) -> None:
    slow, fast = new_codec(255, MONITOR_COMPONENT), new_codec(255, MONITOR_COMPONENT)
    for i in range(300):  # through the sequence number's wrap-around
        command = Command(1 + i % 254, k + i, elev * (i % 3))
        assert fastframe.encode_command(fast, command, 0.02) == encode_command(slow, command, 0.02)
    assert (fast.seq, fast.total_packets_sent, fast.total_bytes_sent) == (
        slow.seq, slow.total_packets_sent, slow.total_bytes_sent)


def test_encode_command_refuses_signed_links() -> None:
    codec = new_codec(255, MONITOR_COMPONENT)
    enable_signing(codec, bytes(range(32)))
    with pytest.raises(ValueError):
        fastframe.encode_command(codec, Command(1, 1, 0.0), 1.0)
