"""The monitor against peers that are not sim-vehicle: one message per datagram, TCP split anywhere,
a vehicle that never sends AOA_SSA, and a second airframe with its own signal map."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np

from monitor.design.result import DesignResult
from monitor.gains import write_gains
from monitor.model.closed_loop import Gains
from monitor.model.plant import load_plant, parse_plant
from monitor.wire.mavlink import mavlink, new_codec
from tests.daemons import REPO, Daemon, free_tcp_port, free_udp_port
from tests.e2e.wire_peer import (
    PeerVehicle,
    check_against_equations,
    fly_tcp_client,
    fly_tcp_server,
    fly_udp,
    read_gains,
)
from tests.monitor_bus import processed_count, wait_ready

STEPS = 60


def _monitor(tmp_path: Path, plant: str, gains: Path, conn: str, name: str, *extra: str) -> Daemon:
    args = [
        "run",
        "--plant",
        plant,
        "--gains",
        str(gains),
        "--mavlink",
        conn,
        "--name",
        name,
        "--zenoh-listen",
        f"tcp/127.0.0.1:{free_tcp_port()}",
        *extra,
    ]
    return Daemon("monitor", args, tmp_path / f"{name}.log")


def _stop(monitor: Daemon) -> str:
    assert monitor.stop() == 0, monitor.log()[-3000:]
    return monitor.log()


def test_one_message_per_datagram_matches_eqs_5_6_computed_from_the_wire(tmp_path: Path, gains_file: Path) -> None:
    plant = load_plant("paper-continuous")
    peer = PeerVehicle(plant, sysid=4, seed=1)
    port = free_udp_port()
    with _monitor(tmp_path, "paper-continuous", gains_file, f"udpin:127.0.0.1:{port}", "udp") as monitor:
        wait_ready(monitor)
        fly_udp(peer, port, STEPS, linger_s=2.5)
        log = _stop(monitor)
    assert processed_count(log) == STEPS, log[-2000:]
    assert sorted(peer.wire.commands) == list(range(STEPS))
    assert check_against_equations(plant, read_gains(gains_file), peer.wire, list(range(STEPS))) == STEPS
    assert any("fault alarm raised" in t for t in peer.wire.statustext), peer.wire.statustext
    assert abs(peer.wire.fhat[STEPS - 1] - 2.0) < 0.1  # and the estimate found the 2-degree bias
    assert "HEARTBEAT" in peer.wire.other  # the monitor's 1 Hz heartbeat reaches its peers


def test_tcp_stream_split_at_random_byte_boundaries(tmp_path: Path, gains_file: Path) -> None:
    """The monitor connects (``tcp:``) to an autopilot-style server that cuts its stream anywhere."""
    plant = load_plant("paper-continuous")
    peer = PeerVehicle(plant, sysid=9, seed=2)
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        with _monitor(tmp_path, "paper-continuous", gains_file, f"tcp:127.0.0.1:{port}", "tcp") as monitor:
            fly_tcp_server(peer, server, STEPS)
            log = _stop(monitor)
    assert processed_count(log) == STEPS, log[-2000:]
    assert check_against_equations(plant, read_gains(gains_file), peer.wire, list(range(STEPS))) == STEPS


def test_tcpin_accepts_a_vehicle_that_connects(tmp_path: Path, gains_file: Path) -> None:
    plant = load_plant("paper-continuous")
    peer = PeerVehicle(plant, sysid=10, seed=4)
    port = free_tcp_port()
    with _monitor(tmp_path, "paper-continuous", gains_file, f"tcpin:127.0.0.1:{port}", "tcpin") as monitor:
        wait_ready(monitor)
        fly_tcp_client(peer, port, STEPS)
        log = _stop(monitor)
    assert processed_count(log) == STEPS, log[-2000:]
    assert check_against_equations(plant, read_gains(gains_file), peer.wire, list(range(STEPS))) == STEPS


def test_a_vehicle_that_never_sends_aoa_ssa_gets_one_warning_naming_it(tmp_path: Path, gains_file: Path) -> None:
    port = free_udp_port()
    codec = new_codec(12, 1)
    with (
        _monitor(tmp_path, "paper-continuous", gains_file, f"udpin:127.0.0.1:{port}", "noaoa") as monitor,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock,
    ):
        wait_ready(monitor)
        start = time.monotonic()
        k = 0
        # the rule: a WARNING once a vehicle was heard for MISSING_WARNING_S (3 s) without a sample, checked at 1 Hz;
        # the vehicle keeps sending until then (bounded at 10 s: a busy machine's late tick is not the monitor's fault)
        while time.monotonic() - start < 10.0 and "never becomes a sample" not in monitor.log():
            codec.send(mavlink.MAVLink_attitude_message(k * 50, 0, 0, 0, 0, 0.01, 0))
            codec.send(mavlink.MAVLink_actuator_output_status_message(k * 50_000, 1, [0.0] * 32))
            sock.sendto(codec.file.take(), ("127.0.0.1", port))
            k += 1
            time.sleep(0.05)
        elapsed = time.monotonic() - start
        log = monitor.log()
    warnings = [line for line in log.splitlines() if "never becomes a sample" in line]
    assert len(warnings) == 1 and 3.0 <= elapsed < 10.0, log[-2000:]  # while it is heard, not before the 3 s
    assert "WARNING" in warnings[0] and "sysid 12" in warnings[0] and "missing AOA_SSA" in warnings[0]


SECOND_AIRFRAME = (REPO / "docs/examples/alpha-q-airframe.toml").read_text()


def test_a_second_airframe_whose_C_reads_alpha_and_q(tmp_path: Path) -> None:
    plant_file = tmp_path / "airframe.toml"
    plant_file.write_text(SECOND_AIRFRAME)
    plant = parse_plant(SECOND_AIRFRAME, str(plant_file))
    # with C = I, L = A makes the state error deadbeat and M = pinv(Df)/2 a stable fault update
    gains = Gains(
        L=plant.A.copy(),
        M=0.5 * np.linalg.pinv(plant.Df),
        K1=np.array([[-0.05, 0.0]]),
        K2=np.zeros((1, 1)),
        K3=np.array([[-0.5]]),
    )
    gains_path = tmp_path / "gains.toml"
    write_gains(
        gains_path,
        DesignResult(
            method="hand", gains=gains, gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0
        ),
        plant,
    )
    peer = PeerVehicle(plant, sysid=5, seed=3, outputs="alpha+q")
    port = free_udp_port()
    with _monitor(tmp_path, str(plant_file), gains_path, f"udpin:127.0.0.1:{port}", "second") as monitor:
        wait_ready(monitor)
        fly_udp(peer, port, 40)
        log = _stop(monitor)
    assert processed_count(log) == 40, log[-2000:]
    assert "y0=AOA_SSA.AOA, y1=ATTITUDE.pitchspeed" in log
    assert check_against_equations(plant, read_gains(gains_path), peer.wire, list(range(40))) == 40


def test_two_links_at_once_and_a_tcp_reconnect(tmp_path: Path, gains_file: Path) -> None:
    """udpin and tcp in one monitor: each vehicle is answered on its own link; the TCP link reconnects."""
    plant = load_plant("paper-continuous")
    udp_peer, tcp_peer = PeerVehicle(plant, sysid=4, seed=5), PeerVehicle(plant, sysid=9, seed=6)
    udp_port = free_udp_port()
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        tcp_port = server.getsockname()[1]
        with _monitor(
            tmp_path,
            "paper-continuous",
            gains_file,
            f"udpin:127.0.0.1:{udp_port}",
            "two",
            "--mavlink",
            f"tcp:127.0.0.1:{tcp_port}",
        ) as monitor:
            wait_ready(monitor)
            fly_udp(udp_peer, udp_port, 25)
            fly_tcp_server(tcp_peer, server, 10)  # the server then drops the connection ...
            fly_tcp_server(tcp_peer, server, 10)  # ... and the monitor comes back (back-off from 0.5 s)
            log = _stop(monitor)
    assert processed_count(log) == 45, log[-2000:]
    assert sorted(udp_peer.wire.commands) == list(range(25))
    assert sorted(tcp_peer.wire.commands) == list(range(20))
    assert check_against_equations(plant, read_gains(gains_file), udp_peer.wire, list(range(25))) == 25
