"""The monitor's MAVLink decoding: samples out, every kind of bad input counted (monitor/service/udp_endpoint.py)."""

from __future__ import annotations


import pytest

from monitor.errors import UserError
from monitor.service.udp_endpoint import MavlinkDecoder, parse_udpin
from monitor.wire.mavlink import (
    VEHICLE_COMPONENT, Command, Sample, enable_signing, encode_heartbeat, encode_sample, mavlink, new_codec,
)
from pymavlink.dialects.v10 import ardupilotmega as mavlink1

H = 1.0


def datagram(codec, k: int, sysid: int = 1, alpha: float = 0.5) -> bytes:
    return encode_sample(codec, Sample(sysid, k, k * H, alpha, 1.0, 0.25), H)


def test_parse_udpin() -> None:
    assert parse_udpin("udpin:127.0.0.1:14550") == ("127.0.0.1", 14550)
    for bad in ("udpout:127.0.0.1:1", "udpin:127.0.0.1", "127.0.0.1:1", "udpin::x"):
        with pytest.raises(UserError):
            parse_udpin(bad)


def test_sample_fields_and_units() -> None:
    dec = MavlinkDecoder()
    [tel] = dec.decode(datagram(new_codec(7, VEHICLE_COMPONENT), 3), "peer")
    assert (tel.sysid, tel.time_usec) == (7, 3_000_000)
    assert tel.alpha_deg == pytest.approx(0.5)
    assert tel.q_deg_s == pytest.approx(1.0, rel=1e-6)  # rad/s on the wire, deg/s out
    assert tel.elevator_deg == pytest.approx(0.25)


def test_garbage_truncation_and_foreign_frames_are_counted_and_harmless() -> None:
    dec, vehicle = MavlinkDecoder(), new_codec(1, VEHICLE_COMPONENT)
    good = datagram(vehicle, 1)
    assert dec.decode(bytes(range(64)) + b"garbage", "p") == []  # no 0xFD/0xFE: urandom made this flaky
    assert dec.decode(good[:50], "p") == []  # ends inside a frame
    assert dec.decode(b"\xfd\x09", "p") == []
    assert len(dec.decode(datagram(vehicle, 2), "p")) == 1  # the leftovers did not eat the next datagram
    bad_crc = bytearray(datagram(vehicle, 3))
    bad_crc[20] ^= 0xFF
    assert dec.decode(bytes(bad_crc), "p") == []  # ATTITUDE corrupted: the AOA_SSA alone is incomplete
    assert dec.decode(encode_heartbeat(vehicle), "p") == []
    other = new_codec(1, VEHICLE_COMPONENT)
    other.send(mavlink.MAVLink_sys_status_message(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0))
    assert dec.decode(other.file.take(), "p") == []
    unknown = bytearray(encode_heartbeat(vehicle))
    unknown[7:10] = b"\x99\x99\x00"  # a message id this dialect does not know
    assert dec.decode(bytes(unknown), "p") == []

    class Sink:
        data = b""

        def write(self, b: bytes) -> None:
            Sink.data += b

    v1 = mavlink1.MAVLink(Sink(), 1, 1)
    v1.send(mavlink1.MAVLink_heartbeat_message(1, 2, 0, 0, 4, 3))
    assert dec.decode(Sink.data, "p") == []
    c = dec.counters
    assert c.garbage >= 2 and c.truncated == 2 and c.incomplete == 1
    assert (c.heartbeats, c.foreign, c.wrong_dialect, c.samples) == (1, 1, 2, 1)


def test_one_parser_per_peer() -> None:
    dec = MavlinkDecoder()
    a, b = datagram(new_codec(1, VEHICLE_COMPONENT), 1), datagram(new_codec(2, VEHICLE_COMPONENT), 1)
    assert dec.decode(a[:40], "A") == []
    assert [t.sysid for t in dec.decode(b, "B")] == [2]  # A's partial frame did not touch B's parser


def test_signing_rejects_unsigned_and_wrong_key_without_poisoning_the_stream() -> None:
    key = bytes(range(32))
    dec = MavlinkDecoder(signing_key=key)
    good, wrong = new_codec(1, VEHICLE_COMPONENT), new_codec(1, VEHICLE_COMPONENT)
    enable_signing(good, key)
    enable_signing(wrong, b"\x01" * 32)
    wrong.signing.timestamp += 10**9  # a forged frame from the future
    assert len(dec.decode(datagram(good, 1), "p")) == 1
    assert dec.decode(datagram(wrong, 2), "p") == []
    assert dec.decode(datagram(new_codec(1, VEHICLE_COMPONENT), 3), "p") == []
    assert len(dec.decode(datagram(good, 4), "p")) == 1  # still accepted after the forgery
    assert dec.counters.bad_signature == 6
    reply = dec.encode_command("p", Command(1, 4, 1.5), H)
    check = new_codec(200, VEHICLE_COMPONENT)
    enable_signing(check, key)
    [msg] = check.parse_buffer(reply)
    assert msg.get_type() == "SET_ACTUATOR_CONTROL_TARGET" and msg.time_usec == 4_000_000
