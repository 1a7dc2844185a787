"""An aircraft about a non-zero operating point, end to end: a real ``fault-monitor run`` (closed loop and
observe-only) against an independent pymavlink peer that flies the 4-state linear plant of
tests/aircraft_files.py in deviation coordinates and puts ABSOLUTE values on the wire
(alpha0 + alpha, ..., the elevator with its trim), VFR_HUD included, one message per datagram in a shuffled
order. The commands on the wire must be u0 + u with u recomputed by the test from eqs. (5)-(6) in deviations,
the 2-degree elevator bias must be estimated within 5 %, and ``analyse`` of the flight's log and ``replay``
of the recording must agree with the live run."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from monitor.link.tlog import TlogWriter
from monitor.model.plant import parse_plant
from monitor.wire.mavlink import mavlink
from tests.aircraft_files import AIRCRAFT_PLANT, LIMIT, OP, U0, Y0, aircraft_files
from tests.daemons import REPO, Daemon, free_tcp_port, free_udp_port, wait_for
from tests.e2e.wire_peer import DEG, PeerVehicle, fly_udp, read_gains
from tests.monitor_bus import processed_count, settling_k, wait_ready

STEPS = 80
ONSET = 20
BIAS = 2.0
K0 = 1_000_000_000 // 50_000  # the peer's clock starts at 1000 s: its sample k is the monitor's K0 + k
OP_LINE = "operating point alpha 2.31 deg, q 0 deg/s, theta 2.31 deg, airspeed 51.4 m/s, elevator -4.3 deg"


def f32(v: float) -> float:
    return float(np.float32(v))


class AircraftPeer(PeerVehicle):
    """``PeerVehicle`` flying a 4-state plant in deviations and sending absolute values, VFR_HUD included.

    It also works out, from the order it sent the messages in, what the monitor's assembler must have used
    for each sample (the contract's rule: VFR_HUD is a latest value, the newest one sent before the sample
    was complete) and keeps those deviations in ``used`` for the check. ``autopilot``: observe-only, the
    vehicle's own law u(k) = autopilot(k, y) in deviations, reported with sample k.
    """

    def __init__(self, plant, sysid: int, seed: int, autopilot=None, tlog: TlogWriter | None = None) -> None:
        super().__init__(plant, sysid, seed, fault_at=ONSET, bias=BIAS)
        self.u_applied = U0  # absolute: at trim
        self.autopilot, self.tlog = autopilot, tlog
        self.used: dict[int, tuple[list[float], float]] = {}  # k -> (y - y0, reported - u0) as the monitor saw them
        self.held: float | None = None  # the monitor's latest airspeed
        self.expect_report = autopilot is not None  # observe-only: the report is part of every sample
        self.u_issued = U0

    def frames(self, k: int) -> list[bytes]:
        t_us = 1_000_000_000 + k * self.h_us
        alpha, q, theta, v = (Y0 + self.x).tolist()
        if self.autopilot is not None:
            y_dev = self.x.copy()
            self.u_issued = U0 + float(np.clip(self.autopilot(k, y_dev), -LIMIT - U0, LIMIT - U0))
            reported = self.u_issued
        else:
            reported = self.u_applied
        y_wire = [f32(alpha) - OP["alpha"], f32(q / DEG) * DEG - OP["q"], f32(theta / DEG) * DEG - OP["theta"]]
        msgs = [
            (
                "ATTITUDE",
                mavlink.MAVLink_attitude_message(
                    (t_us // 1000) & 0xFFFFFFFF, 0.01, theta / DEG, 1.5, 0.0, q / DEG, 0.0
                ),
            ),
            ("AOA_SSA", mavlink.MAVLink_aoa_ssa_message(t_us, alpha, 0.0)),
            ("VFR_HUD", mavlink.MAVLink_vfr_hud_message(v, v, 86, 62, 914.4, 0.0)),
            (
                "ACTUATOR_OUTPUT_STATUS",
                mavlink.MAVLink_actuator_output_status_message(t_us, 1, [reported] + [0.0] * 31),
            ),
        ]
        self.rng.shuffle(msgs)
        if self.rng.random() < 0.2:
            msgs.append(msgs[0])  # a repeated message: counted, never processed twice
        # the assembler's view: the sample goes once ATTITUDE and AOA_SSA are in, an airspeed is held, and its
        # report is in (once the vehicle is known to report); the airspeed is the newest held at that moment
        sent: set[str] = set()
        for name, _msg in msgs:
            if name == "VFR_HUD":
                self.held = f32(v)
            else:
                sent.add(name)
                self.expect_report |= name == "ACTUATOR_OUTPUT_STATUS"
            if (
                k not in self.used
                and {"ATTITUDE", "AOA_SSA"} <= sent
                and self.held is not None
                and (not self.expect_report or "ACTUATOR_OUTPUT_STATUS" in sent)
            ):
                report = f32(reported) if "ACTUATOR_OUTPUT_STATUS" in sent else U0  # k = 0: its own u(-1) = 0
                self.used[k] = ([*y_wire, self.held - OP["airspeed"]], report - U0)
        out = []
        for _name, msg in msgs:
            self.codec.send(msg)
            frame = self.codec.file.take()
            out.append(frame)
            if self.tlog is not None:
                self.tlog.write(int(time.time() * 1e6), frame)
        return out

    def advance(self, k: int) -> None:
        """The plant in deviations: the command (absolute on the wire) minus the trim acts now."""
        p = self.plant
        u_abs = self.u_issued if self.autopilot is not None else self.wire.commands.get(k, self.u_applied)
        f = self.bias if k >= self.fault_at else 0.0
        self.x = p.A @ self.x + (p.B0 * (u_abs - U0) + p.B1 * (self.u_applied - U0) + p.Df * f).ravel()
        self.u_applied = f32(u_abs)


def recompute(
    plant, gains: dict[str, np.ndarray], peer: AircraftPeer, ks: list[int], observe: bool = False, tol: float = 1e-5
) -> int:
    """Eqs. (5)-(6) in deviation coordinates from what crossed the wire; commands must be u0 + u.

    1e-5 (relative, at least 1e-5 absolute): float32 on the wire leaves ~4e-7; using the other sample's VFR_HUD
    (own instead of held, or back) moves a command by ~5e-4, so the check also says which one was used."""
    A, B0, B1, C, Df = plant.A, plant.B0, plant.B1, plant.C, plant.Df
    x, f = np.zeros(plant.n), np.zeros(plant.q)
    compared = 0
    u_prev = np.zeros(1)
    for k in ks:
        y_list, reported = peer.used[k]
        y = np.array(y_list)
        if observe:  # u(k) is the vehicle's, reported with the sample; u(k-1) the previous report
            u = np.array([reported])
        else:
            u_prev = np.array([reported])
            u = np.clip(gains["K1"] @ y + gains["K2"] @ u_prev + gains["K3"] @ f, -LIMIT - U0, LIMIT - U0)
        assert abs(peer.wire.fhat[k] - f[0]) <= tol * max(1.0, abs(f[0])), (k, peer.wire.fhat[k], f[0])
        if not observe:
            assert abs(peer.wire.commands[k] - (U0 + u[0])) <= tol * max(1.0, abs(U0 + u[0])), (
                k,
                peer.wire.commands[k],
                U0 + u[0],
            )
            compared += 1
        r = y - C @ x
        x, f = A @ x + B0 @ u + B1 @ u_prev + Df @ f + gains["L"] @ r, f + gains["M"] @ r
        if observe:
            u_prev = u
    return compared


def _monitor(tmp_path: Path, plant: Path, gains: Path, port: int, zenoh: str, name: str, *extra: str) -> Daemon:
    args = [
        "run",
        "--plant",
        str(plant),
        "--gains",
        str(gains),
        "--mavlink",
        f"udpin:127.0.0.1:{port}",
        "--name",
        name,
        "--zenoh-listen",
        zenoh,
        *extra,
    ]
    return Daemon("monitor", args, tmp_path / f"{name}.log")


def _status(endpoint: str) -> list[dict]:
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    session = open_session(build_config(connect=[endpoint], mode="client"))
    try:
        return [
            json.loads(r.ok.payload.to_bytes())
            for r in session.get("uav/*/fault/status", timeout=3.0)
            if r.ok is not None
        ]
    finally:
        close_quietly(session)


def _cli(*args: str, timeout: float = 60) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "monitor", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_closed_loop_about_an_operating_point_commands_are_absolute(tmp_path: Path) -> None:
    plant_path, gains_path = aircraft_files(tmp_path)
    plant = parse_plant(AIRCRAFT_PLANT, str(plant_path))
    peer = AircraftPeer(plant, sysid=21, seed=7)
    port, zenoh, rrd = free_udp_port(), f"tcp/127.0.0.1:{free_tcp_port()}", tmp_path / "aircraft.rrd"
    with _monitor(tmp_path, plant_path, gains_path, port, zenoh, "aircraft", "--rrd", str(rrd)) as monitor:
        wait_ready(monitor)
        fly_udp(peer, port, STEPS)
        [status] = _status(zenoh)
        assert monitor.stop() == 0, monitor.log()[-3000:]
    log = monitor.log()
    ready = next(line for line in log.splitlines() if "ready:" in line)
    assert ready.endswith(OP_LINE), ready
    assert processed_count(log) == STEPS, log[-2000:]
    assert sorted(peer.wire.commands) == list(range(STEPS))
    assert recompute(plant, read_gains(gains_path), peer, list(range(STEPS))) == STEPS
    # absolute on the wire: at trim the command is the trim deflection; once the bias is cancelled it is u0 - ~2
    assert abs(peer.wire.commands[0] - U0) < 1e-4
    assert -6.5 < peer.wire.commands[STEPS - 1] < -5.9, peer.wire.commands[STEPS - 1]
    fhat = [{"k": k, "f_hat": [v]} for k, v in peer.wire.fhat.items()]
    settled = settling_k(fhat, BIAS, 0.05 * BIAS)
    assert settled is not None and settled - ONSET <= 6, settled
    assert max(abs(peer.wire.fhat[k]) for k in range(ONSET)) < 0.05  # no false fault at trim
    # Zenoh: u is the absolute command that went on the wire; x_hat and f_hat are deviations
    assert status["k"] == K0 + STEPS - 1 and abs(status["u"][0] - peer.wire.commands[STEPS - 1]) < 1e-5
    assert abs(status["f_hat"][0] - BIAS) < 0.1
    # the recording: measured values absolute, the estimator's quantities in deviations; replay scores it
    report = json.loads(_cli("replay", str(rrd), "--json", "--fault", f"bias:{BIAS}@{K0 + ONSET}"))
    vehicle = report["vehicles"]["21"]
    assert vehicle["samples"] == STEPS and vehicle["settling_steps"] is not None and vehicle["settling_steps"] <= 6
    assert json.loads(report["properties"]["operating_point"]) == OP
    from monitor.service.recording_reader import load_recording

    rows = load_recording(rrd).vehicles[21].samples
    assert abs(rows[0].alpha - OP["alpha"]) < 1e-4
    assert abs(next(r.elevator for r in rows if r.elevator is not None) - U0) < 1e-4
    assert abs(rows[0].y[0]) < 1e-4 and abs(rows[-1].u[0] - (peer.wire.commands[STEPS - 1] - U0)) < 1e-5


def _fly_observe(peer: AircraftPeer, port: int, steps: int, wait_s: float = 1.0) -> None:
    """One message per datagram; no command comes back in observe-only mode: wait (bounded) for FHAT."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(0.05)
        for k in range(steps):
            for frame in peer.frames(k):
                sock.sendto(frame, ("127.0.0.1", port))
            deadline = time.monotonic() + wait_s
            while time.monotonic() < deadline and k not in peer.wire.fhat:
                try:
                    peer.receive(sock.recv(65535))
                except TimeoutError:
                    continue
            peer.advance(k)


def test_observe_only_about_an_operating_point_and_analyse_of_the_log(tmp_path: Path) -> None:
    """The vehicle flies itself (a pitch damper plus a doublet, about the trim); the monitor observes. The log of
    what the vehicle sent, analysed offline, gives the live estimates again: the same latest-value rule."""
    plant_path, gains_path = aircraft_files(tmp_path)
    plant = parse_plant(AIRCRAFT_PLANT, str(plant_path))
    tlog_path = tmp_path / "flight.tlog"

    def autopilot(k: int, y: np.ndarray) -> float:
        return -0.02 * y[1] + (1.0 if 5 <= k < 10 else -1.0 if 10 <= k < 15 else 0.0)

    port, zenoh = free_udp_port(), f"tcp/127.0.0.1:{free_tcp_port()}"
    with (
        TlogWriter(tlog_path) as tlog,
        _monitor(tmp_path, plant_path, gains_path, port, zenoh, "observer", "--observe") as monitor,
    ):
        peer = AircraftPeer(plant, sysid=22, seed=8, autopilot=autopilot, tlog=tlog)
        wait_ready(monitor)
        _fly_observe(peer, port, STEPS)
        wait_for(lambda: STEPS - 1 in peer.wire.fhat, 30, what="the last estimate")
        assert monitor.stop() == 0, monitor.log()[-3000:]
    log = monitor.log()
    assert "observe-only" in log and OP_LINE in log
    assert processed_count(log) == STEPS, log[-2000:]
    assert not peer.wire.commands  # observe-only: nothing commanded
    recompute(plant, read_gains(gains_path), peer, list(range(STEPS)), observe=True)
    settled = settling_k([{"k": k, "f_hat": [v]} for k, v in peer.wire.fhat.items()], BIAS, 0.05 * BIAS)
    assert settled is not None and settled - ONSET <= 6, settled

    rrd = tmp_path / "offline.rrd"
    report = json.loads(
        _cli(
            "analyse",
            str(tlog_path),
            "--plant",
            str(plant_path),
            "--gains",
            str(gains_path),
            "--json",
            "--rrd",
            str(rrd),
            "--fault",
            f"bias:{BIAS}@{K0 + ONSET}",
        )
    )
    assert report["log"]["processed"] == STEPS and report["vehicles"]["22"]["settling_steps"] <= 6
    from monitor.service.recording_reader import load_recording

    offline = {r.k - K0: r.f_hat[0] for r in load_recording(rrd).vehicles[22].samples}
    assert sorted(offline) == list(range(STEPS))
    assert max(abs(offline[k] - peer.wire.fhat[k]) for k in range(STEPS)) < 1e-5  # float32 FHAT on the wire
