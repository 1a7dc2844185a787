"""``sim-vehicle run`` as a real daemon, observed from outside: a plain pymavlink client, a Zenoh subscriber,
garbage and unsigned commands on its socket, signals. Loopback only; every wait bounded; every daemon stopped.
"""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import time

import numpy as np
import pytest

from monitor.model.discretize import discretize
from monitor.model.plant import load_plant
from monitor.wire.mavlink import (
    MONITOR_COMPONENT,
    Command,
    enable_signing,
    encode_command,
    new_codec,
    sample_index,
)
from tests.daemons import Daemon, free_tcp_port, free_udp_port, wait_for

PLANT = load_plant("paper-continuous")
EXPECTED_TRUTH_KEYS = {"sysid", "k", "t", "x", "f", "d", "tau"}


def vehicle(tmp_path, port: int, *args: str, name: str = "vehicle") -> Daemon:
    return Daemon("sim_vehicle", ["run", "--mavlink", f"udpout:127.0.0.1:{port}", *args], tmp_path / f"{name}.log")


def datagrams(d: Daemon, rx: socket.socket, timeout: float = 30.0):
    """Yield ``(datagram, source)`` reaching ``rx`` until the daemon exits (bounded by ``timeout``)."""
    rx.settimeout(0.2)
    deadline = time.monotonic() + timeout
    while d.proc.poll() is None and time.monotonic() < deadline:
        try:
            yield rx.recvfrom(4096)
        except TimeoutError:
            continue


def read_jsonl(path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_plain_pymavlink_client_reads_the_vehicle_and_closes_the_loop(tmp_path):
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import mavutil

    port, gain = free_udp_port(), 0.5
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="ardupilotmega", source_system=255)
    seen: dict[str, list] = {"HEARTBEAT": [], "ATTITUDE": [], "AOA_SSA": [], "ACTUATOR_OUTPUT_STATUS": []}
    try:
        with vehicle(
            tmp_path,
            port,
            "--steps",
            "30",
            "--speedup",
            "10",
            "--no-zenoh",
            "--fault",
            "bias:2@10",
            "--x0",
            "1,0",
            "--truth-jsonl",
            str(tmp_path / "truth.jsonl"),
            "--summary-json",
            str(tmp_path / "summary.json"),
        ) as d:
            deadline = time.monotonic() + 30
            while d.proc.poll() is None and time.monotonic() < deadline:
                msg = conn.recv_match(blocking=True, timeout=0.2)
                if msg is None or msg.get_type() not in seen:
                    continue
                seen[msg.get_type()].append(msg)
                if msg.get_type() == "AOA_SSA":  # the naive controller: u = -gain * alpha
                    controls = [0.0] * 8
                    controls[1] = -gain * msg.AOA / 30.0
                    conn.mav.set_actuator_control_target_send(msg.time_usec, 0, 1, 1, controls)
            assert d.wait(15) == 0, d.log()
    finally:
        conn.close()
    assert seen["HEARTBEAT"] and seen["HEARTBEAT"][0].type == mavutil.mavlink.MAV_TYPE_FIXED_WING
    assert [sample_index(m.time_usec, 1.0) for m in seen["AOA_SSA"]] == list(range(30))
    truth = read_jsonl(tmp_path / "truth.jsonl")
    assert [t["k"] for t in truth] == list(range(30)) and all(t["status"] == "applied" for t in truth)
    # units on the wire: AOA in degrees, pitch rate in rad/s, elevator in degrees
    for att, aoa, act, t in zip(seen["ATTITUDE"], seen["AOA_SSA"], seen["ACTUATOR_OUTPUT_STATUS"], truth, strict=True):
        assert aoa.AOA == pytest.approx(t["x"][0], abs=1e-5)
        assert att.pitchspeed == pytest.approx(math.radians(t["x"][1]), abs=1e-6)
        assert act.actuator[0] == pytest.approx(t["elevator"], abs=1e-5) and act.time_usec == aoa.time_usec
    # the plant physics: model (2) with the true tau(k) and the commands the controller sent
    x = np.array(truth[0]["x"])
    u_prev = 0.0
    for row, nxt in zip(truth, truth[1:], strict=False):
        u = row["u"][0]
        assert u == pytest.approx(-gain * row["x"][0], abs=1e-5)
        D = discretize(PLANT.continuous, PLANT.h, row["tau"])
        x = D.A @ x + D.B0[:, 0] * u + D.B1[:, 0] * u_prev + D.Df[:, 0] * row["f"][0] + D.Dd[:, 0] * row["d"][0]
        assert np.allclose(x, nxt["x"], atol=1e-9)
        u_prev = u
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["commands"]["applied"] == 30 and summary["samples"]["taken"] == 30
    drawn, true = summary["tau_drawn"], summary["tau"]
    assert 0 <= drawn["min"] and drawn["max"] <= PLANT.tau_max and true["min"] >= drawn["min"] - 1e-9


def test_truth_reaches_a_zenoh_subscriber_as_json(tmp_path):
    import zenoh

    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    zport = free_tcp_port()
    session = open_session(build_config(listen=[f"tcp/127.0.0.1:{zport}"]))
    got: list = []
    sub = session.declare_subscriber(
        "e2e/**", lambda s: got.append((str(s.key_expr), s.encoding, s.payload.to_bytes()))
    )
    try:
        with vehicle(
            tmp_path,
            free_udp_port(),
            "--steps",
            "12",
            "--speedup",
            "8",
            "--sysid",
            "7",
            "--key-prefix",
            "e2e/net1",
            "--zenoh-connect",
            f"tcp/127.0.0.1:{zport}",
        ) as d:
            assert d.wait(20) == 0, d.log()
        wait_for(lambda: any(json.loads(p)["k"] == 11 for _, _, p in got), 30, what="the last truth sample")
    finally:
        close_quietly(session, sub)
    assert {k for k, _, _ in got} == {"e2e/net1/7/truth"}
    assert all(str(e) == str(zenoh.Encoding.APPLICATION_JSON) for _, e, _ in got)
    payloads = [json.loads(p) for _, _, p in got]
    assert all(EXPECTED_TRUTH_KEYS <= set(p) and p["sysid"] == 7 and p["tau"] is None for p in payloads)
    assert len(payloads) >= 10  # nobody answers: every tau is null (lost)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_the_daemon_cleanly(tmp_path, sig):
    with vehicle(tmp_path, free_udp_port(), "--speedup", "5") as d:
        wait_for(lambda: "sending to udp" in d.log(), 15, what="the vehicle to start")
        time.sleep(0.3)
        d.signal(sig)
        assert d.wait(10) == 0, d.log()
        assert "sim-vehicle summary" in d.log() and "Traceback" not in d.log()


def test_garbage_and_unsigned_commands_are_counted_and_signed_ones_applied(tmp_path):
    key = bytes(range(32))
    (tmp_path / "key.hex").write_text(key.hex())
    port, bind = free_udp_port(), free_udp_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    good, unsigned, forger = (
        new_codec(255, MONITOR_COMPONENT),
        new_codec(255, MONITOR_COMPONENT),
        new_codec(255, MONITOR_COMPONENT),
    )
    enable_signing(good, key)
    enable_signing(forger, os.urandom(32))
    verifier = new_codec(255, MONITOR_COMPONENT)
    enable_signing(verifier, key, sign_outgoing=False)
    target = ("127.0.0.1", bind)
    sent_bad = 0
    try:
        with vehicle(
            tmp_path,
            port,
            "--steps",
            "20",
            "--speedup",
            "10",
            "--no-zenoh",
            "--bind",
            f"127.0.0.1:{bind}",
            "--signing-key",
            str(tmp_path / "key.hex"),
            "--summary-json",
            str(tmp_path / "s.json"),
        ) as d:
            for data, _ in datagrams(d, rx):
                msgs = verifier.parse_buffer(data) or []
                assert msgs and all(m.get_type() != "BAD_DATA" for m in msgs)  # the vehicle signs its frames
                for m in msgs:
                    if m.get_type() != "AOA_SSA":
                        continue
                    k = sample_index(m.time_usec, 1.0)
                    frame = encode_command(good, Command(1, k, 1.0), 1.0)
                    for junk in (
                        os.urandom(64),
                        frame[:17],
                        encode_command(unsigned, Command(1, k, 9.0), 1.0),
                        encode_command(forger, Command(1, k, 9.0), 1.0),
                    ):
                        rx.sendto(junk, target)
                        sent_bad += 1
                    rx.sendto(frame, target)
                    rx.sendto(frame, target)  # replayed
            assert d.wait(15) == 0, d.log()
    finally:
        rx.close()
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["commands"]["applied"] == 20 and s["samples"]["applied"] == 20
    assert s["packets"]["rejected_signature"] == 20 * 3  # unsigned, wrong key, replay
    assert s["packets"]["garbage"] >= 1 and s["packets"]["truncated"] >= 1


def test_user_errors_are_one_line_and_exit_2(tmp_path):
    bad_config = tmp_path / "v.toml"
    bad_config.write_text('dealy = "const:0.1"\n')
    cases = [
        ["--fault", "bias@2"],
        ["--delay", "uniform:2:1"],
        ["--plant", "nope"],
        ["--sysid", "300"],
        ["--mavlink", "tcp:1.2.3.4:5"],
        ["--config", str(bad_config)],
        ["--loss", "2"],
    ]
    for extra in cases:
        with vehicle(tmp_path, free_udp_port(), "--no-zenoh", *extra, name="err") as d:
            assert d.wait(20) == 2, (extra, d.log())
            lines = d.log().strip().splitlines()
            assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in d.log(), (extra, d.log())


def test_help_and_config_file(tmp_path):
    with Daemon("sim_vehicle", ["run", "--help"], tmp_path / "help.log") as d:
        assert d.wait(20) == 0
        assert "--fault" in d.log() and "udpout" in d.log() and "examples" in d.log()
    conf = tmp_path / "v.toml"
    conf.write_text(f'steps = 3\nspeedup = 20\nno_zenoh = true\nmavlink = "udpout:127.0.0.1:{free_udp_port()}"\n')
    with Daemon(
        "sim_vehicle", ["run", "--config", str(conf), "--summary-json", str(tmp_path / "s.json")], tmp_path / "conf.log"
    ) as d:
        assert d.wait(20) == 0, d.log()
    assert json.loads((tmp_path / "s.json").read_text())["samples"]["taken"] == 3


def test_emulated_loss_duplication_and_reordering_follow_the_seeded_draws(tmp_path):
    from sim_vehicle.network import DOWNLINK, UPLINK, Impairment

    steps, seed = 60, 11
    imp = Impairment(loss=0.2, duplicate=0.2, reorder=0.1, seed=seed)
    port = free_udp_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    mav, parser = new_codec(255, MONITOR_COMPONENT), new_codec(255, MONITOR_COMPONENT)
    answered: set[int] = set()
    arrivals: list[int] = []
    try:
        with vehicle(
            tmp_path,
            port,
            "--steps",
            str(steps),
            "--speedup",
            "10",
            "--no-zenoh",
            "--seed",
            str(seed),
            "--loss",
            "0.2",
            "--duplicate",
            "0.2",
            "--reorder",
            "0.1",
            "--summary-json",
            str(tmp_path / "s.json"),
        ) as d:
            for data, src in datagrams(d, rx):
                for m in parser.parse_buffer(data) or []:
                    if m.get_type() == "AOA_SSA":
                        k = sample_index(m.time_usec, 1.0)
                        arrivals.append(k)
                        if k not in answered:  # answer each sample once, so each command is copy 0
                            answered.add(k)
                            rx.sendto(encode_command(mav, Command(1, k, 0.0), 1.0), src)
            assert d.wait(15) == 0, d.log()
    finally:
        rx.close()
    s = json.loads((tmp_path / "s.json").read_text())
    fates = [imp.fate(UPLINK, k) for k in range(steps)]
    assert s["samples"]["dropped"] == sum(not f for f in fates)
    assert s["samples"]["duplicated"] == sum(len(f) == 2 for f in fates)
    assert s["samples"]["reordered"] == sum(bool(f) and f[0][1] == "reordered" for f in fates)
    delivered = {k for k, f in enumerate(fates) if f}
    assert {k for k in delivered if k < steps - 2} <= set(arrivals) <= delivered  # late copies may outlive the run
    assert arrivals != sorted(arrivals)  # reordering is visible on the wire
    assert s["commands"]["dropped"] == sum(not imp.fate(DOWNLINK, k, 0) for k in answered)
    assert s["samples"]["applied"] + s["samples"]["late"] + s["samples"]["lost"] == steps
