"""A vehicle that is not ``sim-vehicle``: other framings, other transports, and an independent check.

The peer encodes with pymavlink (not the project's encoder), sends each sample as separate messages in a
shuffled order (one per datagram on UDP; on TCP one byte stream cut at random boundaries), repeats some,
and integrates its own discrete plant with the command it receives. Everything that crossed the wire is
kept, and ``check_against_equations`` recomputes eqs. (5)-(6) from those values alone, with the gains read
from the gains file by ``tomllib``: the monitor's commands and its ``FHAT`` feedback must match to 1e-3.
"""

from __future__ import annotations

import math
import random
import socket
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monitor.wire.mavlink import mavlink, new_codec

DEG = 180.0 / math.pi


@dataclass
class Wire:
    """What crossed the wire, per sample k (plant units as the vehicle put them on the wire)."""

    y: dict[int, list[float]] = field(default_factory=dict)
    reported: dict[int, float] = field(default_factory=dict)
    commands: dict[int, float] = field(default_factory=dict)
    fhat: dict[int, float] = field(default_factory=dict)
    statustext: list[str] = field(default_factory=list)
    other: list[str] = field(default_factory=list)


class PeerVehicle:
    """Discrete plant x+ = A x + B0 u(k) + B1 u(k-1) + Df f; telemetry per the contract, any framing."""

    def __init__(
        self, plant, sysid: int, seed: int, outputs: str = "alpha", fault_at: int = 20, bias: float = 2.0
    ) -> None:
        self.k_next = 0  # flights continue where the last one stopped (a reconnect)
        self.plant, self.sysid, self.rng = plant, sysid, random.Random(seed)
        self.codec = new_codec(sysid, 1)
        self.rx = new_codec(sysid, 1)
        self.outputs, self.fault_at, self.bias = outputs, fault_at, bias
        self.h_us = int(round(plant.h * 1e6))
        self.x = np.zeros(plant.n)
        self.u_applied = 0.0
        self.u_prev = 0.0
        self.wire = Wire()

    def frames(self, k: int) -> list[bytes]:
        t_us = 1_000_000_000 + k * self.h_us  # the vehicle's own epoch: k need not start at 0
        alpha, q = float(self.x[0]), float(self.x[1])
        a32, q32, e32 = (float(np.float32(v)) for v in (alpha, q / DEG, self.u_applied))
        self.wire.y[k] = [a32] if self.outputs == "alpha" else [a32, float(np.float32(q32 * np.float32(DEG)))]
        self.wire.reported[k] = e32
        msgs = [
            mavlink.MAVLink_attitude_message((t_us // 1000) & 0xFFFFFFFF, 0, 0, 0, 0, q / DEG, 0),
            mavlink.MAVLink_aoa_ssa_message(t_us, alpha, 0.0),
            mavlink.MAVLink_actuator_output_status_message(t_us, 1, [self.u_applied] + [0.0] * 31),
        ]
        self.rng.shuffle(msgs)
        out = []
        for m in msgs:
            self.codec.send(m)
            out.append(self.codec.file.take())
        if self.rng.random() < 0.2:
            out.append(out[0])  # a repeated message: counted, never processed twice
        if self.rng.random() < 0.2:
            self.codec.send(mavlink.MAVLink_vfr_hud_message(20.0, 20.0, 0, 50, 100.0, 0.0))  # routers carry more
            out.insert(1, self.codec.file.take())
        return out

    def receive(self, data: bytes) -> None:
        for msg in self.rx.parse_buffer(data) or []:
            kind = msg.get_type()
            if kind == "SET_ACTUATOR_CONTROL_TARGET":
                k = round((msg.time_usec - 1_000_000_000) / self.h_us)
                self.wire.commands[k] = msg.controls[1] * 30.0
            elif kind == "NAMED_VALUE_FLOAT" and msg.name == "FHAT":
                self.wire.fhat[round((msg.time_boot_ms * 1000 - 1_000_000_000) / self.h_us)] = msg.value
            elif kind == "STATUSTEXT":
                self.wire.statustext.append(msg.text)
            else:
                self.wire.other.append(kind)

    def advance(self, k: int) -> None:
        """The command for k (if it came) acts now; the plant steps to k+1."""
        p = self.plant
        u = self.wire.commands.get(k, self.u_applied)  # a command that did not come: the actuator holds
        f = self.bias if k >= self.fault_at else 0.0
        self.x = p.A @ self.x + (p.B0 * u + p.B1 * self.u_applied + p.Df * f).ravel()
        self.u_applied = float(np.float32(u))


def read_gains(path: Path) -> dict[str, np.ndarray]:
    g = tomllib.loads(Path(path).read_text())["gains"]
    return {n: np.array(g[n], dtype=float) for n in ("L", "M", "K1", "K2", "K3")}


def check_against_equations(
    plant, gains: dict[str, np.ndarray], wire: Wire, ks: list[int], limit: float = 30.0, tol: float = 1e-3
) -> int:
    """Eqs. (5)-(6) on the wire's values; returns how many commands were compared."""
    A, B0, B1, C, Df = plant.A, plant.B0, plant.B1, plant.C, plant.Df
    x, f = np.zeros(plant.n), np.zeros(plant.q)
    compared = 0
    for k in ks:
        y = np.array(wire.y[k])
        u_prev = np.array([wire.reported[k]])
        u = np.clip(gains["K1"] @ y + gains["K2"] @ u_prev + gains["K3"] @ f, -limit, limit)
        assert abs(wire.fhat[k] - f[0]) <= tol * max(1.0, abs(f[0])), (k, wire.fhat[k], f[0])
        if k in wire.commands:
            assert abs(wire.commands[k] - u[0]) <= tol * max(1.0, abs(u[0])), (k, wire.commands[k], u[0])
            compared += 1
        r = y - C @ x
        x, f = A @ x + B0 @ u + B1 @ u_prev + Df @ f + gains["L"] @ r, f + gains["M"] @ r
    return compared


def fly_udp(peer: PeerVehicle, port: int, steps: int, wait_s: float = 1.0, linger_s: float = 0.0) -> None:
    """One message per datagram to the monitor's udpin; wait (bounded) for each sample's answer.

    ``linger_s``: then keep listening until a HEARTBEAT comes (the monitor's 1 Hz one), at most this long.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(0.05)
        for k in range(peer.k_next, peer.k_next + steps):
            for frame in peer.frames(k):
                sock.sendto(frame, ("127.0.0.1", port))
            _await(lambda: sock.recv(65535), peer, k, wait_s)
            peer.advance(k)
        peer.k_next += steps
        deadline = time.monotonic() + linger_s
        while time.monotonic() < deadline and "HEARTBEAT" not in peer.wire.other:
            try:
                peer.receive(sock.recv(65535))
            except TimeoutError:
                continue


def fly_tcp_server(peer: PeerVehicle, server: socket.socket, steps: int, wait_s: float = 1.0) -> None:
    """An autopilot-style TCP server (SITL on 5760): the monitor connects with ``tcp:``."""
    server.settimeout(15)
    conn, _ = server.accept()
    fly_tcp_stream(peer, conn, steps, wait_s)


def fly_tcp_client(peer: PeerVehicle, port: int, steps: int, wait_s: float = 1.0) -> None:
    """A vehicle or router that connects to the monitor's ``tcpin:`` port."""
    conn = socket.create_connection(("127.0.0.1", port), timeout=5)
    fly_tcp_stream(peer, conn, steps, wait_s)


def fly_tcp_stream(peer: PeerVehicle, conn: socket.socket, steps: int, wait_s: float = 1.0) -> None:
    """The byte stream of each sample cut at random boundaries, each piece its own write."""
    with conn:
        conn.settimeout(0.05)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for k in range(peer.k_next, peer.k_next + steps):
            data = b"".join(peer.frames(k))
            cuts = sorted(peer.rng.sample(range(1, len(data)), 6))
            for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True):
                conn.sendall(data[a:b])
                time.sleep(0.001)  # separate reads on the other side, splitting frames for real
            _await(lambda: conn.recv(65535), peer, k, wait_s)
            peer.advance(k)
        peer.k_next += steps


def _await(recv, peer: PeerVehicle, k: int, wait_s: float) -> None:
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline and not (k in peer.wire.commands and k in peer.wire.fhat):
        try:
            peer.receive(recv())
        except (TimeoutError, BlockingIOError):
            continue
