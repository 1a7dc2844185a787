"""``sim-vehicle run --aircraft c172p`` as a real daemon: a plain pymavlink listener, a client that commands it
after its identification manoeuvre, MAVProxy recording the manoeuvre, and seeded turbulence across processes.
Loopback only; every wait bounded; every process stopped."""

from __future__ import annotations

import json
import math
import socket
import time
from collections import defaultdict
from pathlib import Path

import pytest

from monitor.wire.mavlink import MONITOR_COMPONENT, Command, encode_command, new_codec, sample_index
from tests.daemons import Daemon, free_udp_port, wait_for

H = 0.05
TELEMETRY = ["ATTITUDE", "AOA_SSA", "VFR_HUD", "ACTUATOR_OUTPUT_STATUS"]


def aircraft(tmp_path: Path, port: int, *args: str, name: str = "aircraft") -> Daemon:
    return Daemon(
        "sim_vehicle",
        ["run", "--aircraft", "c172p", "--mavlink", f"udpout:127.0.0.1:{port}", "--no-zenoh", *args],
        tmp_path / f"{name}.log",
    )


def read_jsonl(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def listen(d: Daemon, rx: socket.socket, on_sample=None, timeout: float = 30.0) -> tuple[dict, list[str]]:
    """Per sample k, the messages of the datagram that carried its AOA_SSA; and every message type seen."""
    parser = new_codec(255, MONITOR_COMPONENT)
    per_k: dict[int, dict] = {}
    seen: list[str] = []
    rx.settimeout(0.2)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            data, src = rx.recvfrom(65535)
        except TimeoutError:
            if d.proc.poll() is not None:
                break
            continue
        msgs = parser.parse_buffer(data) or []
        seen += [m.get_type() for m in msgs]
        by_type = {m.get_type(): m for m in msgs}
        if "AOA_SSA" in by_type:
            k = sample_index(by_type["AOA_SSA"].time_usec, H)
            per_k[k] = by_type
            if on_sample is not None:
                on_sample(k, by_type, src)
    return per_k, seen


def test_every_sample_carries_the_contract_plus_pitch_and_airspeed_and_the_prbs_is_reported(tmp_path):
    port = free_udp_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    truth_file, summary = tmp_path / "truth.jsonl", tmp_path / "summary.json"
    try:
        with aircraft(
            tmp_path,
            port,
            "--rate",
            "20",
            "--steps",
            "200",
            "--speedup",
            "50",
            "--excite",
            "prbs:1:5",
            "--truth-jsonl",
            str(truth_file),
            "--summary-json",
            str(summary),
        ) as d:
            per_k, seen = listen(d, rx)
            assert d.wait(20) == 0, d.log()
    finally:
        rx.close()
    assert sorted(per_k) == list(range(200)), d.log()[-2000:]
    assert seen.count("HEARTBEAT") >= 10  # 1 Hz of simulated time over 10 s
    truth = read_jsonl(truth_file)
    assert [t["k"] for t in truth] == list(range(200))
    trim = truth[0]["trim"]
    for k, msgs in per_k.items():
        assert list(msgs) == TELEMETRY  # one datagram per sample: VFR_HUD travels with its sample
        att, aoa, hud, act = (msgs[name] for name in TELEMETRY)
        assert aoa.time_usec == k * 50_000 and act.time_usec == k * 50_000 and att.time_boot_ms == k * 50
        x = truth[k]["x"]  # alpha deg, q deg/s, theta deg, airspeed m/s
        assert aoa.AOA == pytest.approx(x[0], abs=1e-5) and att.pitch == pytest.approx(math.radians(x[2]), abs=1e-6)
        assert att.pitchspeed == pytest.approx(math.radians(x[1]), abs=1e-6)
        assert hud.airspeed == pytest.approx(x[3], abs=1e-4) and 45 < hud.airspeed < 60
    issued = [per_k[k]["ACTUATOR_OUTPUT_STATUS"].actuator[0] for k in range(200)]
    levels = {round(u - trim, 4) for u in issued[:100]}
    assert levels == {-1.0, 1.0}, levels  # +-1 deg about the trim deflection for 5 s ...
    assert all(u == pytest.approx(trim, abs=1e-5) for u in issued[100:])  # ... then trim, held
    s = json.loads(summary.read_text())
    assert s["samples"]["taken"] == 200 and s["samples"]["onboard"] == 101 and s["packets"]["send_errors"] == 0
    assert s["commands"].get("applied", 0) == 0  # the manoeuvre is flown on board: no command was received


def test_after_its_manoeuvre_the_aircraft_follows_commands_it_ignored_during_it(tmp_path):
    port = free_udp_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    codec = new_codec(255, MONITOR_COMPONENT)

    def answer(k, msgs, src):  # an absolute elevator of 3 deg, normalised by 30 deg in controls[1]
        rx.sendto(encode_command(codec, Command(1, k, 3.0), H), src)

    truth_file, summary = tmp_path / "truth.jsonl", tmp_path / "summary.json"
    try:
        with aircraft(
            tmp_path,
            port,
            "--steps",
            "60",
            "--speedup",
            "2",
            "--excite",
            "prbs:1:1",
            "--delay",
            "const:0.01",
            "--truth-jsonl",
            str(truth_file),
            "--summary-json",
            str(summary),
        ) as d:
            per_k, _ = listen(d, rx, on_sample=answer)
            assert d.wait(20) == 0, d.log()
    finally:
        rx.close()
    s = json.loads(summary.read_text())
    assert s["commands"]["ignored_excitation"] == 21  # samples 0..20: the PRBS, then trim
    truth = read_jsonl(truth_file)
    followed = [t for t in truth[22:] if t["surface"] == pytest.approx(3.0, abs=1e-6)]
    assert len(followed) >= 30, [t["surface"] for t in truth]
    assert per_k[59]["ACTUATOR_OUTPUT_STATUS"].actuator[0] == pytest.approx(3.0, abs=1e-5)
    assert "ignored while flying on board (autopilot/excitation) 21" in d.log()


def test_light_turbulence_is_the_same_flight_in_another_process_with_the_same_seed(tmp_path):
    def flight(seed: int, name: str) -> list[dict]:
        path = tmp_path / f"{name}.jsonl"
        with aircraft(
            tmp_path,
            free_udp_port(),
            "--steps",
            "80",
            "--speedup",
            "1000",
            "--turbulence",
            "light",
            "--seed",
            str(seed),
            "--truth-jsonl",
            str(path),
            name=name,
        ) as d:
            assert d.wait(20) == 0, d.log()
        return read_jsonl(path)

    a, b, c = flight(7, "a"), flight(7, "b"), flight(8, "c")
    assert len(a) == 80 and a == b
    assert [t["x"] for t in a] != [t["x"] for t in c]


def test_mavproxy_records_the_manoeuvre_in_its_tlog(tmp_path):
    from pymavlink import mavutil

    from tests.e2e.mavproxy_router import MavProxy

    master, out = free_udp_port(), free_udp_port()
    steps = 120
    with MavProxy(tmp_path, master, out) as mp:
        with aircraft(
            tmp_path,
            master,
            "--steps",
            str(steps),
            "--speedup",
            "10",
            "--excite",
            "prbs:2:4",
            "--truth-jsonl",
            str(tmp_path / "truth.jsonl"),
        ) as d:
            assert d.wait(30) == 0, d.log()

        def records() -> dict[str, dict[int, object]]:
            log = mavutil.mavlink_connection(str(mp.tlog), dialect="ardupilotmega")
            got: dict[str, dict[int, object]] = defaultdict(dict)
            while (msg := log.recv_match(blocking=False)) is not None:
                if msg.get_type() in ("AOA_SSA", "ACTUATOR_OUTPUT_STATUS"):
                    got[msg.get_type()][sample_index(msg.time_usec, H)] = msg
                elif msg.get_type() in ("ATTITUDE", "VFR_HUD", "HEARTBEAT"):
                    got[msg.get_type()][len(got[msg.get_type()])] = msg
            return got

        wait_for(lambda: mp.tlog.exists() and len(records()["AOA_SSA"]) >= steps, 15, what="the tlog's last sample")
        mp.stop()
    got = records()
    assert sorted(got["ACTUATOR_OUTPUT_STATUS"]) == list(range(steps))
    assert len(got["ATTITUDE"]) >= steps and len(got["VFR_HUD"]) >= steps and got["HEARTBEAT"]
    trim = read_jsonl(tmp_path / "truth.jsonl")[0]["trim"]
    issued = [got["ACTUATOR_OUTPUT_STATUS"][k].actuator[0] for k in range(steps)]
    assert {round(u - trim, 4) for u in issued[:80]} == {-2.0, 2.0}
    assert all(abs(u - trim) < 1e-5 for u in issued[80:])
