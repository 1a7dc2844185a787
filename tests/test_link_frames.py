"""The frame layer against pymavlink: parsing any framing, every reject counted, encoding byte for byte."""

from __future__ import annotations

import random

import pytest

from monitor.link.dialect import layout_by_name
from monitor.link.frames import FrameCounters, FrameEncoder, FrameParser
from monitor.link.outgoing import alarm_text_frame, command_frame, fhat_frames, heartbeat_frame
from monitor.link.signals import default_signal_map
from monitor.link.signing import Signer
from monitor.wire.mavlink import FrameSink, mavlink, new_codec

KEY = bytes(range(32))


def _telemetry(codec, k: int) -> list[bytes]:
    """Three frames of one sample, encoded by pymavlink (the independent encoder)."""
    t_us = k * 20_000
    msgs = [
        mavlink.MAVLink_attitude_message(t_us // 1000, 0.1, 0.2, 0.3, 0.0, 0.05 * k, 0.0),
        mavlink.MAVLink_aoa_ssa_message(t_us, 1.5 + k, 0.0),
        mavlink.MAVLink_actuator_output_status_message(t_us, 1, [float(-k)] + [0.0] * 31),
    ]
    return [m.pack(codec) for m in msgs]


def _decoded(frames) -> list[tuple]:
    return [
        (msgid, sysid, compid, layout_by_name(mavlink.mavlink_map[msgid].msgname).decode(payload))
        for msgid, sysid, compid, payload in frames
    ]


def _reference(frames_bytes: list[bytes]) -> list[tuple]:
    """What pymavlink itself decodes from the same bytes, in the parser's output shape."""
    codec = new_codec(255, 1)
    out = []
    for msg in codec.parse_buffer(b"".join(frames_bytes)) or []:
        assert msg.get_type() != "BAD_DATA", msg
        layout = layout_by_name(msg.get_type())
        buf = msg.get_msgbuf()
        header = 6 if buf[0] == 0xFE else 10
        decoded = layout.decode(buf[header:-2])
        # pymavlink's own values, in the layout's flat wire order: the payload slice is not trusted alone
        flat = []
        for name in layout.fields:
            value = getattr(msg, name)
            flat.extend(value if isinstance(value, list) else [value])
        assert [v.rstrip(b"\x00").decode() if isinstance(v, bytes) else v for v in decoded] == flat
        out.append((msg.get_msgId(), msg.get_srcSystem(), msg.get_srcComponent(), decoded))
    return out


def _v1_codec(sysid: int, compid: int = 1):
    """pymavlink's MAVLink 1 encoder (its v1 dialect module: base fields only, no truncation, no signing)."""
    from pymavlink.dialects.v10 import ardupilotmega as v1

    return v1, v1.MAVLink(FrameSink(), srcSystem=sysid, srcComponent=compid)


def _telemetry_v1(k: int, sysid: int = 4) -> list[bytes]:
    """What an ArduPilot vehicle on a MAVLink 1 link sends: messages with ids below 256, one with extensions
    (SERVO_OUTPUT_RAW, STATUSTEXT), zeros at the end of the payload (which v1 keeps), encoded by pymavlink."""
    v1, codec = _v1_codec(sysid)
    t_us = 123_456_789 + k * 20_000
    msgs = [
        v1.MAVLink_attitude_message(t_us // 1000, 0.1, -0.02 * k, 0.3, 0.0, 0.05 * k, 0.0),
        v1.MAVLink_servo_output_raw_message(t_us & 0xFFFFFFFF, 0, 1500, 1500 + 10 * k, 1000, 0, 0, 0, 0, 0),
        v1.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3),
        v1.MAVLink_statustext_message(6, b"v1 text %d" % k),
        v1.MAVLink_named_value_float_message(k, b"X", 0.0),
    ]
    return [m.pack(codec) for m in msgs]


def test_mavlink1_frames_give_pymavlink_values_packed_or_one_each() -> None:
    frames = [f for k in range(4) for f in _telemetry_v1(k)]
    assert all(f[0] == 0xFE for f in frames)
    expected = _reference(frames)
    assert len(expected) == 20
    counters = FrameCounters()
    parser = FrameParser(counters)
    assert _decoded(parser.feed(b"".join(frames))) == expected
    assert parser.version == 1
    assert _decoded([f for data in frames for f in parser.feed(data)]) == expected
    assert counters.frames == counters.frames_v1 == 40
    assert counters.garbage == counters.truncated == counters.wrong_dialect == 0


@pytest.mark.parametrize("seed", range(5))
def test_mavlink1_and_2_mixed_on_a_stream_split_anywhere(seed: int) -> None:
    vehicle = new_codec(3, 1)
    data = b"".join(f for k in range(10) for f in (*_telemetry(vehicle, k), *_telemetry_v1(k, sysid=5)))
    rng = random.Random(seed)
    cuts = sorted(rng.sample(range(1, len(data)), 150))
    pieces = [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True)]
    c = FrameCounters()
    parser = FrameParser(c, stream=True)
    got = [f for piece in pieces for f in parser.feed(piece)]
    assert _decoded(got) == _reference([data])
    assert c.frames == 80 and c.frames_v1 == 50 and c.garbage == 0


def test_a_signed_link_refuses_mavlink1_frames() -> None:
    vehicle = new_codec(2, 1)
    vehicle.signing.secret_key, vehicle.signing.sign_outgoing = KEY, True
    from monitor.wire.mavlink import bump_signing_clock

    bump_signing_clock(vehicle)
    c = FrameCounters()
    parser = FrameParser(c, Signer(KEY))
    assert parser.feed(b"".join(_telemetry_v1(1))) == []
    assert c.v1_refused == 5 and c.frames == c.frames_v1 == c.bad_signature == c.garbage == 0
    assert len(parser.feed(b"".join(_telemetry(vehicle, 1)))) == 3 and parser.version == 2
    with pytest.raises(ValueError, match="cannot be signed"):
        FrameEncoder(255, 191, Signer(KEY), version=1)


def test_datagram_packed_or_one_message_each_gives_pymavlink_values() -> None:
    vehicle = new_codec(7, 1)
    frames = [f for k in range(5) for f in _telemetry(vehicle, k)]
    expected = _reference(frames)
    assert len(expected) == 15
    counters = FrameCounters()
    parser = FrameParser(counters)
    assert _decoded(parser.feed(b"".join(frames))) == expected
    assert _decoded([f for data in frames for f in parser.feed(data)]) == expected
    assert counters.frames == 30 and counters.garbage == counters.truncated == 0


@pytest.mark.parametrize("seed", range(5))
def test_stream_split_anywhere_keeps_partial_frames(seed: int) -> None:
    vehicle = new_codec(3, 1)
    data = b"".join(f for k in range(20) for f in _telemetry(vehicle, k))
    rng = random.Random(seed)
    cuts = sorted(rng.sample(range(1, len(data)), 150))
    pieces = [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True)]
    parser = FrameParser(FrameCounters(), stream=True)
    got = [f for piece in pieces for f in parser.feed(piece)]
    assert _decoded(got) == _reference([data])


def test_garbage_bad_crc_truncation_and_other_dialects_are_counted_and_good_frames_survive() -> None:
    vehicle = new_codec(1, 1)
    good = _telemetry(vehicle, 1)
    bad_crc = bytearray(good[0])
    bad_crc[-1] ^= 0xFF
    v1 = bytes([0xFE, 1, 0, 1, 1, 0, 0, 0, 0])  # a MAVLink 1 frame shape (CRC not even valid)
    unknown = bytes([0xFD, 1, 0, 0, 0, 1, 1, 0xFF, 0xFF, 0x7F, 0, 0, 0])  # msgid 0x7fffff
    c = FrameCounters()
    parser = FrameParser(c)
    out = parser.feed(b"junk!!" + bytes(bad_crc) + good[1] + unknown + good[2])
    assert [f[0] for f in out] == [mavlink.MAVLINK_MSG_ID_AOA_SSA, mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS]
    assert c.garbage == 1 and c.wrong_dialect == 1  # junk and the bad-CRC frame after it: one run
    assert parser.feed(good[0][:-3]) == [] and c.truncated == 1
    assert len(parser.feed(good[0])) == 1  # the truncated datagram did not swallow the next one
    parser.feed(v1)
    assert c.garbage == 2  # a v1 frame whose CRC fails is junk, not a frame


def _send(codec, msg) -> bytes:
    codec.send(msg)  # send (not pack) advances the sequence number, as a real sender does
    return codec.file.take()


def test_encoder_matches_pymavlink_byte_for_byte() -> None:
    enc, ref = FrameEncoder(255, 191), new_codec(255, 191)
    cmd = default_signal_map().command
    for k in range(3):
        ours = command_frame(enc, cmd, 4, k * 20_000, [12.5 * (k - 1)])
        controls = [0.0] * 8
        controls[1] = 12.5 * (k - 1) / 30.0
        theirs = _send(ref, mavlink.MAVLink_set_actuator_control_target_message(k * 20_000, 0, 4, 1, controls))
        assert ours == theirs
    assert fhat_frames(enc, 40_000, [1.25]) == _send(ref, mavlink.MAVLink_named_value_float_message(40, b"FHAT", 1.25))
    text = alarm_text_frame(enc, 4, "raised", 2.5, "deg")
    msg = new_codec(1, 1).parse_buffer(text)[0]
    assert msg.get_type() == "STATUSTEXT" and msg.severity == mavlink.MAV_SEVERITY_WARNING
    assert "fault alarm" in msg.text and "sysid 4" in msg.text
    hb = new_codec(1, 1).parse_buffer(heartbeat_frame(enc))[0]
    assert hb.get_type() == "HEARTBEAT" and hb.type == mavlink.MAV_TYPE_ONBOARD_CONTROLLER


def test_mavlink1_encoder_matches_pymavlink_v1_byte_for_byte() -> None:
    v1, ref = _v1_codec(255, 191)
    enc = FrameEncoder(255, 191, version=1)
    cmd = default_signal_map().command
    for k in range(3):
        controls = [0.0] * 8
        controls[1] = 12.5 * (k - 1) / 30.0
        ref.send(v1.MAVLink_set_actuator_control_target_message(k * 20_000, 0, 4, 1, controls))
        assert command_frame(enc, cmd, 4, k * 20_000, [12.5 * (k - 1)]) == ref.file.take()
    ref.send(v1.MAVLink_named_value_float_message(40, b"FHAT", 0.0))  # all-zero tail: v1 keeps it
    assert fhat_frames(enc, 40_000, [0.0]) == ref.file.take()
    ref.send(v1.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, b"sysid 4 fault alarm raised |fhat| 2.5 deg"))
    assert alarm_text_frame(enc, 4, "raised", 2.5, "deg") == ref.file.take()  # no extension fields in v1
    ref.send(
        v1.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
        )
    )
    assert heartbeat_frame(enc) == ref.file.take()
    # what v1 cannot carry (an id above 255) goes out in MAVLink 2, and our parser reads both back
    frame = enc.encode(layout_by_name("AOA_SSA"), (1_000, 2.5, 0.0))
    assert frame[0] == 0xFD
    c = FrameCounters()
    assert [f[0] for f in FrameParser(c).feed(frame)] == [mavlink.MAVLINK_MSG_ID_AOA_SSA] and c.frames_v1 == 0


def test_signed_frames_verify_both_ways_and_replays_are_refused_across_peers() -> None:
    vehicle = new_codec(2, 1)
    vehicle.signing.secret_key, vehicle.signing.sign_outgoing, vehicle.signing.link_id = KEY, True, 3
    from monitor.wire.mavlink import bump_signing_clock

    bump_signing_clock(vehicle)
    frames = _telemetry(vehicle, 1)
    c = FrameCounters()
    signer = Signer(KEY)
    udp_peer_a, udp_peer_b = FrameParser(c, signer), FrameParser(c, signer)  # two source ports, one signer
    assert len(udp_peer_a.feed(b"".join(frames))) == 3
    assert udp_peer_b.feed(b"".join(frames)) == [] and c.bad_signature == 3  # replay from a new port
    unsigned = _telemetry(new_codec(2, 1), 2)
    assert udp_peer_a.feed(unsigned[0]) == [] and c.bad_signature == 4
    wrong = new_codec(2, 1)
    wrong.signing.secret_key, wrong.signing.sign_outgoing = bytes(32), True
    wrong.signing.timestamp = vehicle.signing.timestamp + 10**9  # a forged future timestamp must not poison
    assert udp_peer_a.feed(_telemetry(wrong, 3)[0]) == [] and c.bad_signature == 5
    assert len(udp_peer_a.feed(b"".join(_telemetry(vehicle, 4)))) == 3
    # and what we sign, pymavlink accepts
    receiver = new_codec(2, 1)
    receiver.signing.secret_key, receiver.signing.sign_outgoing = KEY, False
    receiver.signing.allow_unsigned_callback = None
    ours = command_frame(FrameEncoder(255, 191, Signer(KEY)), default_signal_map().command, 2, 0, [1.0])
    assert [m.get_type() for m in receiver.parse_buffer(ours)] == ["SET_ACTUATOR_CONTROL_TARGET"]


def test_values_beyond_float32_are_sent_as_infinity_not_a_crash() -> None:
    frame = fhat_frames(FrameEncoder(255, 191), 0, [1e300])
    msg = new_codec(1, 1).parse_buffer(frame)[0]
    assert msg.value == float("inf")
