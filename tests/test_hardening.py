"""What no packet, sender or lost command may do to an estimate (the vehicle table and pipeline, no sockets)."""

from __future__ import annotations

import logging
import math
import random

import numpy as np
import pytest

from monitor.link.dialect import layout_by_name
from monitor.link.frames import FrameCounters, FrameEncoder, FrameParser
from monitor.link.signing import Signer
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.pipeline import Pipeline
from monitor.service.vehicles import VehicleTable
from monitor.wire.mavlink import mavlink, new_codec
from tests.gains_files import hand_made_gains_file

AOA, ACT = layout_by_name("AOA_SSA"), layout_by_name("ACTUATOR_OUTPUT_STATUS")


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return load_model("paper-continuous", hand_made_gains_file(tmp_path_factory.mktemp("g") / "gains.toml"))


def aoa(k: int, alpha: float = 0.1) -> tuple:
    return AOA.decode(AOA.unpacker.pack(k * 1_000_000, alpha, 0.0))


def act(k: int, elevator: float) -> tuple:
    return ACT.decode(ACT.unpacker.pack(k * 1_000_000, 1, elevator, *[0.0] * 31))


def run(table: VehicleTable, sysid: int, k: int, route: str, now: float, alpha: float = 0.1, elevator=None):
    ready = []
    if elevator is not None:
        ready += table.message(sysid, "ACTUATOR_OUTPUT_STATUS", act(k, elevator), route, now)
    ready += table.message(sysid, "AOA_SSA", aoa(k, alpha), route, now)
    return [table.process(v, s, 0.0, now) for v, s in ready]


def test_non_finite_and_out_of_range_inputs_never_reach_the_estimator(model) -> None:
    table = VehicleTable(Fleet(model), AlarmConfig())
    assert run(table, 1, 0, "A", 0.0)[0] is not None
    state = table.vehicles[1].state.z.copy()
    assert run(table, 1, 1, "A", 0.1, alpha=float("nan")) == [None]
    assert run(table, 1, 2, "A", 0.2, alpha=1e6) == [None]
    assert np.array_equal(table.vehicles[1].state.z, state) and table.counters.rejected_values == 2
    p = run(table, 1, 3, "A", 0.3)[0]
    assert p.result.skipped == 2 and all(math.isfinite(v) for v in table.vehicles[1].state.z)


def test_a_sysid_speaks_only_from_its_source_while_that_source_is_live(model) -> None:
    table = VehicleTable(Fleet(model), AlarmConfig(), restart_silence=1.0)
    for k in range(5):
        run(table, 1, k, "vehicle", k * 0.02)
    assert run(table, 1, 5, "spoofer", 0.1, alpha=50.0) == []  # a k+1 follower from another port
    assert table.counters.foreign_source == 1
    assert run(table, 1, 5, "vehicle", 0.1)[0].result.k == 5
    moved = run(table, 1, 6, "router", 1.5)  # the vehicle went quiet for 1.4 s and came back through a router
    assert moved[0].result.k == 6 and table.vehicles[1].route == "router"


def test_a_far_future_instant_is_refused_and_cannot_lock_the_vehicle_out(model) -> None:
    table = VehicleTable(Fleet(model), AlarmConfig())
    for k in range(3):
        run(table, 1, k, "A", k * 0.02)
    assert run(table, 1, 1_000_000, "A", 0.05) == []
    assert table.vehicles[1].assembler.counters.future == 1
    assert run(table, 1, 3, "A", 0.06)[0].result.k == 3


def test_commands_that_do_not_act_are_noticed_and_the_estimator_uses_the_held_deflection(model, caplog) -> None:
    table = VehicleTable(Fleet(model), AlarmConfig())
    p = run(table, 1, 0, "A", 0.0, elevator=0.0)[0]
    held = 0.0
    with caplog.at_level(logging.WARNING):
        for k in range(1, 12):
            sent = table.vehicles[1].last_command[0]
            p = run(table, 1, k, "A", k * 0.02, alpha=0.5, elevator=held)[0]  # the actuator never moves
            assert p.command_applied is (abs(sent - held) < 1e-9)
            assert table.vehicles[1].state.u_prev[0] == pytest.approx(p.result.u[0])
    v = table.vehicles[1]
    assert not v.commands_effective and table.counters.not_applied >= 5
    assert sum("not taking effect" in r.message for r in caplog.records) == 1
    # the estimator stepped with what acted: u(k-1) in its state at k was the held 0, not its own command
    p = run(table, 1, 12, "A", 0.3, alpha=0.5, elevator=held)[0]
    assert p.command_applied is False
    ok = run(table, 1, 13, "A", 0.32, alpha=0.5, elevator=float(np.float32(p.result.u[0])))[0]
    assert ok.command_applied is True


class _DatagramLink:
    datagram = True

    def __init__(self) -> None:
        self.encoder = FrameEncoder(255, 191)
        self.sent: list[bytes] = []

    def encoder_for(self, peer) -> FrameEncoder:
        return self.encoder

    def send(self, data: bytes, peer) -> None:
        self.sent.append(data)


def test_one_datagram_buys_at_most_one_answer(model) -> None:
    codec = new_codec(1, 1)
    packed = b""
    for k in range(800):  # ~800 valid samples in one 64 KB datagram: an 800x reflection before
        codec.send(mavlink.MAVLink_aoa_ssa_message(k * 1_000_000, 0.1, 0.0))
        packed += codec.file.take()
    pipeline = Pipeline(VehicleTable(Fleet(model), AlarmConfig()))
    link = _DatagramLink()
    frames = FrameParser(pipeline.frames).feed(packed)
    assert len(frames) == 800
    pipeline.on_frames((link, ("127.0.0.1", 5)), frames, 0)
    assert pipeline.table.counters.processed == 1 and pipeline.commands_sent == 1
    assert pipeline.messages.excess == 799


def _captured() -> list[bytes]:
    """Valid frames as a vehicle sends them (telemetry, heartbeat, text), unsigned and signed."""
    out = []
    for signed in (False, True):
        codec = new_codec(4, 1)
        if signed:
            codec.signing.secret_key, codec.signing.sign_outgoing = bytes(range(32)), True
            from monitor.wire.mavlink import bump_signing_clock

            bump_signing_clock(codec)
        for k in range(4):
            for msg in (
                mavlink.MAVLink_attitude_message(k * 20, 0, 0, 0, 0, 0.1, 0),
                mavlink.MAVLink_aoa_ssa_message(k * 20_000, 1.0 + k, 0.0),
                mavlink.MAVLink_actuator_output_status_message(k * 20_000, 1, [0.5] + [0.0] * 31),
                mavlink.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3),
                mavlink.MAVLink_statustext_message(4, b"hello", 0, 0),
            ):
                codec.send(msg)
                out.append(codec.file.take())
    return out


def _mutate(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        kind = rng.random()
        if kind < 0.5 and b:
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        elif kind < 0.7 and b:
            del b[rng.randrange(len(b)) :]
        elif kind < 0.85:
            b[rng.randrange(len(b) + 1) : 0] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif b:
            i = rng.randrange(len(b))
            b[i : i + 1] = b"\xfd"
    return bytes(b)


def _content(frame: bytes) -> tuple:
    """(msgid, sysid, payload) of one original frame, as pymavlink decodes it."""
    msg = new_codec(255, 1).parse_buffer(frame)[0]
    buf = msg.get_msgbuf()
    return msg.get_msgId(), msg.get_srcSystem(), bytes(buf[10 : 10 + buf[1]])


@pytest.mark.parametrize("signed", [False, True])
def test_mutation_fuzz_of_captured_frames(model, signed: bool) -> None:
    """Bit flips, truncation, junk and stray start bytes: never an exception, every frame that comes out is one
    that went in intact (pymavlink decodes the originals), and the pipeline never holds a non-finite state."""
    rng = random.Random(7 if signed else 3)
    frames = _captured()
    originals = {_content(data) for data in frames}
    pipeline = Pipeline(VehicleTable(Fleet(model), AlarmConfig()))
    link = _DatagramLink()
    signer = Signer(bytes(range(32))) if signed else None
    stream = FrameParser(FrameCounters(), signer, stream=True)
    for i in range(3000):
        data = _mutate(rng, b"".join(rng.sample(frames, rng.randint(1, 3))))
        ours = FrameParser(FrameCounters(), Signer(bytes(range(32))) if signed else None).feed(data)
        for msgid, sysid, _comp, payload in ours:
            assert (msgid, sysid, bytes(payload)) in originals
        stream.feed(data)
        pipeline.on_frames(
            (link, ("127.0.0.1", i)), FrameParser(pipeline.frames, signer).feed(data), 0, now=i * 0.01, wall=i * 0.01
        )
    for vehicle in pipeline.table.vehicles.values():
        assert all(math.isfinite(v) for v in vehicle.state.z)
    assert pipeline.frames.garbage > 0


def test_a_clock_that_really_jumped_is_believed_after_a_while_but_a_forged_stamp_is_not(model) -> None:
    table = VehicleTable(Fleet(model), AlarmConfig())
    for k in range(3):
        run(table, 1, k, "A", k * 0.02)
    epoch = 1_700_000_000  # the vehicle switched its stamps from boot time to Unix time
    t = 0.06
    forged = run(table, 1, 10**6, "A", t)  # a single forged stamp amid ordinary samples: refused ...
    assert forged == [] and run(table, 1, 3, "A", t + 0.01)[0].result.k == 3  # ... and forgotten
    for i in range(12):
        t += 0.25
        done = run(table, 1, epoch + i, "A", t)
    assert done and done[0].result.k == epoch + 11 and table.counters.restarts == 1
    moved = run(table, 1, 5 * epoch, "B", t + 5.0)  # a new source after silence with a far-off clock: at once
    assert moved and moved[0].result.k == 5 * epoch and table.counters.restarts == 2
