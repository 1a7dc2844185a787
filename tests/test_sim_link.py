"""The vehicle's MAVLink receive side (sim_vehicle/link.py): garbage, truncation, foreign frames, signing."""

from __future__ import annotations

import hashlib
import os

import pytest

from monitor.errors import UserError
from monitor.wire.mavlink import MONITOR_COMPONENT, Command, enable_signing, encode_command, encode_heartbeat, new_codec
from sim_vehicle.link import CommandDecoder, load_signing_key

KEY = bytes(range(32))
SRC = ("127.0.0.1", 40000)


def monitor(key: bytes | None = None):
    mav = new_codec(255, MONITOR_COMPONENT)
    if key is not None:
        enable_signing(mav, key)
    return mav


def cmd(mav, k: int, u: float = 6.0, sysid: int = 1) -> bytes:
    return encode_command(mav, Command(sysid, k, u), 1.0)


def test_a_command_is_decoded_in_plant_units():
    dec = CommandDecoder(1, 1.0)
    (c,) = dec.feed(cmd(monitor(), 7, -4.5), SRC)
    assert c.k == 7 and c.elevator_deg == pytest.approx(-4.5, abs=1e-5)


def test_garbage_truncated_and_foreign_are_counted_and_later_frames_still_decode():
    dec = CommandDecoder(1, 1.0)
    mav = monitor()
    assert dec.feed(b"hello, not mavlink at all " * 8, SRC) == []
    assert dec.feed(cmd(mav, 1)[:15], SRC) == []
    assert dec.feed(cmd(mav, 2, sysid=9), SRC) == []
    assert dec.feed(encode_heartbeat(mav, vehicle=False), SRC) == []
    assert [c.k for c in dec.feed(b"\x00junk" + cmd(mav, 3) + cmd(mav, 4), SRC)] == [3, 4]
    assert dec.packets["garbage"] >= 1 and dec.packets["truncated"] == 1 and dec.packets["other"] == 1
    assert dec.commands["foreign_target"] == 1


def test_signing_rejects_unsigned_wrong_key_and_replayed_commands():
    dec = CommandDecoder(1, 1.0, KEY)
    good = monitor(KEY)
    assert dec.feed(cmd(monitor(), 1), SRC) == []  # unsigned
    assert dec.feed(cmd(monitor(os.urandom(32)), 2), SRC) == []  # wrong key
    frame = cmd(good, 3)
    assert [c.k for c in dec.feed(frame, SRC)] == [3]
    assert dec.feed(frame, SRC) == []  # replayed
    assert dec.feed(frame, ("127.0.0.1", 40001)) == []  # replayed from another port: one signing state
    assert dec.packets["rejected_signature"] == 4


def test_a_forged_frame_with_a_future_timestamp_does_not_poison_the_stream():
    dec = CommandDecoder(1, 1.0, KEY)
    good, forger = monitor(KEY), monitor(os.urandom(32))
    assert [c.k for c in dec.feed(cmd(good, 1), SRC)] == [1]
    forger.signing.timestamp = good.signing.timestamp + 10**9  # same stream (link 0, 255, 191), far future
    assert dec.feed(cmd(forger, 2), SRC) == []
    assert [c.k for c in dec.feed(cmd(good, 3), SRC)] == [3]


def test_signing_key_file_forms(tmp_path):
    raw = tmp_path / "raw.key"
    raw.write_bytes(KEY)
    hexed = tmp_path / "hex.key"
    hexed.write_text(KEY.hex() + "\n")
    phrase = tmp_path / "phrase.txt"
    phrase.write_text("correct horse\n")
    assert load_signing_key(raw) == KEY == load_signing_key(hexed)
    assert load_signing_key(phrase) == hashlib.sha256(b"correct horse").digest()
    (tmp_path / "empty").write_text("  \n")
    for bad in (tmp_path / "empty", tmp_path / "missing"):
        with pytest.raises(UserError, match="--signing-key"):
            load_signing_key(bad)
