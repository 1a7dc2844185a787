"""``--mavlink`` connection strings and the operator mistakes around them: one line, exit 2."""

from __future__ import annotations

import socket
import subprocess
import sys
import time

import pytest

from monitor.errors import UserError
from monitor.link.transports import ConnectionSpec, parse_connection, resolve
from tests.mavlink1_signals import V1_SIGNALS


@pytest.mark.parametrize(
    "text, spec",
    [
        ("udpin:127.0.0.1:14550", ConnectionSpec("udpin", "127.0.0.1", 14550)),
        ("udp:127.0.0.1:14550", ConnectionSpec("udpin", "127.0.0.1", 14550)),
        ("udpout:localhost:14551", ConnectionSpec("udpout", "localhost", 14551)),
        ("tcp:127.0.0.1:5760", ConnectionSpec("tcp", "127.0.0.1", 5760)),
        ("tcpin:[::1]:5761", ConnectionSpec("tcpin", "::1", 5761)),
    ],
)
def test_connections_as_mavproxy_writes_them(text: str, spec: ConnectionSpec) -> None:
    assert parse_connection(text) == spec


@pytest.mark.parametrize(
    "text",
    ["udpin:127.0.0.1", "serial:/dev/ttyUSB0:57600", "tcp:127.0.0.1:0", "udpin:127.0.0.1:70000", "127.0.0.1:14550"],
)
def test_bad_connections_are_one_line(text: str) -> None:
    with pytest.raises(UserError, match="expected udpin:HOST:PORT|needs the peer's port"):
        parse_connection(text)


def test_an_unresolvable_host_is_one_line() -> None:
    with pytest.raises(UserError, match="cannot resolve host 'no-such-host.invalid'"):
        resolve(parse_connection("udpout:no-such-host.invalid:14550"))


def test_mavlink_port_in_use_is_one_line_exit_2(tmp_path) -> None:
    from tests.gains_files import hand_made_gains_file

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "run",
                "--plant",
                "paper-continuous",
                "--gains",
                str(gains),
                "--mavlink",
                f"udpin:127.0.0.1:{port}",
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if "error" in line]
    assert len(lines) == 1 and "in use" in lines[0] and "Traceback" not in out.stderr, out.stderr


@pytest.mark.parametrize(
    "endpoint, message",
    [
        ("tcp/256.1.1.1:7447", "not a valid IP address"),
        ("tcp/127.0.0.1", "PROTOCOL/HOST:PORT with a port"),
        ("foo", "expected PROTOCOL/HOST:PORT"),
        ("tcp/no-such-host.invalid:7447", "cannot resolve host"),
    ],
)
def test_bad_zenoh_endpoints_are_one_line_errors(endpoint: str, message: str) -> None:
    from monitor.wire.zenoh_session import build_config

    with pytest.raises(UserError, match=message):
        build_config(connect=[endpoint])


def test_zenoh_errors_lose_their_rust_source_paths() -> None:
    from monitor.wire.zenoh_session import build_config, open_session

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(UserError) as err:
            open_session(build_config(listen=[f"tcp/127.0.0.1:{port}"]))
    assert "Address already in use" in str(err.value) and ".rs:" not in str(err.value)


def test_operator_mistakes_on_run_are_one_line_exit_2(tmp_path) -> None:
    from tests.gains_files import hand_made_gains_file

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    fleet = tmp_path / "fleet.toml"
    fleet.write_text("vehicle = 3\n")
    cases = [
        (["--queue", "0"], "--queue must be at least 1"),
        (["--zenoh-connect", "tcp/256.1.1.1:7447"], "not a valid IP address"),
        (["--fleet", str(fleet)], "'vehicle' must be tables"),
        (["--mavlink", "udpin:no-such-host.invalid:14550"], "cannot resolve host"),
    ]
    for extra, message in cases:
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "run",
                "--plant",
                "paper-continuous",
                "--gains",
                str(gains),
                "--mavlink",
                "udpin:127.0.0.1:0",
                *extra,
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert out.returncode == 2 and message in out.stderr, (extra, out.stderr)
        assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr


def test_a_closed_stdout_pipe_is_a_quiet_exit(tmp_path) -> None:
    """``fault-monitor subscribe | head``: every command runs through run_cli_command, which must stay quiet."""
    script = (
        "import sys, types; from monitor.errors import run_cli_command\n"
        "args = types.SimpleNamespace(command='subscribe', func=lambda a: [print('x' * 100) for _ in range(10**5)])\n"
        "sys.exit(run_cli_command('fault-monitor', args))\n"
    )
    (tmp_path / "talk.py").write_text(script)
    proc = subprocess.run(
        f"{sys.executable} {tmp_path / 'talk.py'} | head -c 10 > /dev/null; echo ${{PIPESTATUS[0]}}",
        shell=True,
        executable="/bin/bash",
        capture_output=True,
        timeout=60,
    )
    assert proc.stderr == b"", proc.stderr
    assert proc.stdout.strip() == b"2"


def _v1_sample(codec, v1, k: int) -> bytes:
    """One sample from a vehicle that speaks MAVLink 1 (ids below 256 only), as one datagram."""
    t_us = k * 1_000_000
    return v1.MAVLink_attitude_message(t_us // 1000, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0).pack(
        codec
    ) + v1.MAVLink_servo_output_raw_message(t_us, 0, 1500, 1500, 1500, 0, 0, 0, 0, 0).pack(codec)


@pytest.mark.parametrize("signed", [False, True])
def test_a_mavlink1_peer_is_answered_in_mavlink1_and_a_signed_link_refuses_it(tmp_path, caplog, signed) -> None:
    """Replies (command, FHAT, heartbeat) go to a v1 peer as v1 frames pymavlink reads; a v2 peer on the same
    link still gets v2. A signed link refuses v1 (counted, one WARNING, in the summary) and answers nothing."""
    import logging

    from pymavlink.dialects.v10 import ardupilotmega as v1

    from monitor.link.signing import Signer
    from monitor.link.transports import open_link
    from monitor.service.alarm import AlarmConfig
    from monitor.service.fleet_file import Fleet, load_model
    from monitor.service.pipeline import Pipeline
    from monitor.service.vehicles import VehicleTable
    from monitor.wire.mavlink import mavlink, new_codec
    from tests.gains_files import hand_made_gains_file

    (tmp_path / "signals.toml").write_text(V1_SIGNALS)
    model = load_model(
        "paper-continuous", hand_made_gains_file(tmp_path / "gains.toml"), signals_file=tmp_path / "signals.toml"
    )
    pipeline = Pipeline(VehicleTable(Fleet(model), AlarmConfig()))
    link = open_link(
        parse_connection("udpin:127.0.0.1:0"),
        0,
        pipeline.on_reads,
        pipeline.frames,
        Signer(bytes(range(32))) if signed else None,
    )
    sent: list[tuple[bytes, object]] = []
    link.send = lambda data, peer: sent.append((data, peer))  # type: ignore[method-assign]
    old_peer, new_peer = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
    codec = v1.MAVLink(None, srcSystem=3, srcComponent=1)
    for k in range(3):
        link.on_datagram(_v1_sample(codec, v1, k), old_peer, time.perf_counter_ns())
    if signed:
        assert sent == [] and pipeline.frames.v1_refused == 6 and pipeline.frames.frames == 0
        with caplog.at_level(logging.WARNING, logger="monitor.run"):
            assert pipeline.warn_frames() and not pipeline.warn_frames()
        assert sum("MAVLink 1 frames refused" in r.message for r in caplog.records) == 1
        assert "MAVLink 1 refused (signed link) 6" in pipeline.summary()
        return
    assert pipeline.table.counters.processed == 3 and pipeline.frames.frames_v1 == 6
    assert "MAVLink 1 frames 6" in pipeline.summary()
    link.heartbeat()
    replies = b"".join(data for data, peer in sent if peer == old_peer)
    reader = new_codec(255, 1)
    msgs = reader.parse_buffer(replies)
    assert [m.get_type() for m in msgs] == ["SET_ACTUATOR_CONTROL_TARGET", "NAMED_VALUE_FLOAT"] * 3 + ["HEARTBEAT"]
    assert all(m.get_msgbuf()[0] == 0xFE for m in msgs) and [m.get_seq() for m in msgs] == list(range(7))
    assert [m.time_usec for m in msgs[::2][:3]] == [0, 1_000_000, 2_000_000]
    # the same vehicle now speaks MAVLink 2 from another port: answered in MAVLink 2
    sent.clear()
    v2 = new_codec(3, 1)
    v2.send(mavlink.MAVLink_attitude_message(3000, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0))
    v2.send(mavlink.MAVLink_servo_output_raw_message(3_000_000, 0, 1500, 1500, 1500, 0, 0, 0, 0, 0))
    pipeline.table.restart_silence = 0.0  # let the new port take over at once
    link.on_datagram(v2.file.take(), new_peer, time.perf_counter_ns())
    assert sent and all(data[0] == 0xFD for data, _peer in sent)
    assert not link.speaks_v1(new_peer) and link.speaks_v1(old_peer)
