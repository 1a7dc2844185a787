"""The attacks of the hardening issue, run against real daemons, with the vehicle's own summary as judge.

A relay in the test stands between the vehicle and the monitor (the monitor sees it as the vehicle's
source): it can corrupt one sample with a NaN angle of attack and slip a far-future stamp in on the
vehicle's own path, while other sockets spoof the vehicle's system id and flood the monitor with junk.
"""

from __future__ import annotations

import json
import math
import os
import socket
import threading
from pathlib import Path

from monitor.wire.mavlink import mavlink, new_codec
from tests.daemons import free_udp_port, wait_for
from tests.monitor_bus import monitor_daemon, processed_count, settling_k, sim_daemon, wait_ready, zenoh_bus

STEPS, SPEEDUP, ONSET, NAN_AT = 60, 20, 20, 32  # NaN once f_hat has settled: it must stay settled


def _summary(log: str, name: str) -> int:
    import re

    match = re.search(rf"[ ,]{name} (\d+)", log.split("stopped:")[-1])
    assert match, log[-1500:]
    return int(match.group(1))


class Relay:
    """vehicle -> relay -> monitor and back; ``tamper(data)`` may rewrite what goes up."""

    def __init__(self, monitor_port: int, tamper=None) -> None:
        self.port = free_udp_port()
        self.monitor = ("127.0.0.1", monitor_port)
        self.down = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.down.bind(("127.0.0.1", self.port))
        self.down.settimeout(0.02)
        self.up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.up.bind(("127.0.0.1", 0))
        self.up.setblocking(False)
        self.tamper = tamper
        self.captured: list[bytes] = []
        self.vehicle = None
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self.stop.is_set():
            try:
                data, self.vehicle = self.down.recvfrom(65535)
                self.captured.append(data)
                self.up.sendto(self.tamper(data) if self.tamper else data, self.monitor)
            except TimeoutError:
                pass
            try:
                while True:
                    reply = self.up.recv(65535)
                    if self.vehicle:
                        self.down.sendto(reply, self.vehicle)
            except BlockingIOError:
                pass

    def __enter__(self) -> Relay:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(5)
        self.down.close()
        self.up.close()


def _nan_at(k_target: int, relay_codec):
    """Rewrite the vehicle's packed sample k_target with AOA = NaN, and once send a far-future stamp."""
    state = {"future_sent": False}

    def tamper(data: bytes) -> bytes:
        msgs = new_codec(255, 1).parse_buffer(data) or []
        out = b""
        changed = False
        for m in msgs:
            if m.get_type() == "AOA_SSA" and round(m.time_usec / 1e6) == k_target:
                m.AOA, changed = float("nan"), True
            if m.get_type() in ("ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS", "HEARTBEAT"):
                relay_codec.send(m)
                out += relay_codec.file.take()
        if changed and not state["future_sent"]:
            state["future_sent"] = True
            relay_codec.send(mavlink.MAVLink_aoa_ssa_message(10**12, 5.0, 0.0))  # k = 10^6 on the vehicle's path
            out += relay_codec.file.take()
        return out if msgs else data

    return tamper


def test_nan_spoofing_far_future_and_flood(tmp_path: Path, gains_file: Path) -> None:
    port = free_udp_port()
    vehicle_json = tmp_path / "vehicle.json"
    stop = threading.Event()
    sent = {"spoof": 0, "flood": 0}

    def attack() -> None:
        spoof = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        codec = new_codec(1, 1)  # claims to be vehicle 1
        floods = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(200)]
        i = 0
        while not stop.is_set():
            for k in (10**6 + i, i // 2 + 1):  # far-future and plausible k+1 followers with a big alpha
                codec.send(mavlink.MAVLink_aoa_ssa_message(k * 1_000_000, 50.0, 0.0))
                spoof.sendto(codec.file.take(), ("127.0.0.1", port))
                sent["spoof"] += 1
            for s in floods[(i * 20) % 200 : (i * 20) % 200 + 20]:
                s.sendto(os.urandom(64), ("127.0.0.1", port))
                sent["flood"] += 1
            i += 1
            stop.wait(0.01)
        for s in (spoof, *floods):
            s.close()

    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        truth = bus.collect("uav/*/truth")
        with monitor_daemon(tmp_path, gains_file, port, bus, "attacked") as monitor:
            wait_ready(monitor)
            attacker = threading.Thread(target=attack, daemon=True)
            with Relay(port, _nan_at(NAN_AT, new_codec(1, 1))) as relay:
                try:
                    with sim_daemon(
                        tmp_path,
                        relay.port,
                        bus,
                        1,
                        "--fault",
                        f"bias:2@{ONSET}",
                        "--summary-json",
                        str(vehicle_json),
                        steps=STEPS,
                        speedup=SPEEDUP,
                    ) as sim:
                        # the attack starts once the vehicle flies: on an unsigned link whoever speaks first for
                        # a system id is believed (README, threat model); signing is the remedy for that
                        wait_for(lambda: len(estimates) >= 2, 20, what="the vehicle's first estimates")
                        attacker.start()
                        assert sim.wait(60) == 0, sim.log()
                finally:
                    stop.set()
                    attacker.join(5)
            wait_for(lambda: len(estimates) >= STEPS - 1, 30, what="estimates")
            assert monitor.stop() == 0
            log = monitor.log()
    summary = json.loads(vehicle_json.read_text())
    assert summary["commands"].get("applied", 0) >= 0.95 * STEPS, summary
    ks = sorted(e["k"] for e in estimates)
    assert NAN_AT not in ks and len(ks) == STEPS - 1, ks  # the NaN sample never reached the estimator
    assert all(all(math.isfinite(v) for v in e["f_hat"] + e["x_hat"] + e["u"]) for e in estimates)
    # 10 %, not the usual 5 %: at 20x under this flood, scheduling jitter pushes the true delay beyond the
    # certified interval (0.66 s measured vs tau_max 0.4612 s), and f_hat then wanders by up to ~0.15 deg;
    # what this test guards is that the attacks themselves (NaN, spoofing, far future, junk) do not move it
    settled = settling_k(estimates, 2.0, 0.2)
    trace = [
        (e["k"], round(e["f_hat"][0], 3), e.get("command_applied"), e.get("tau"))
        for e in sorted(estimates, key=lambda e: e["k"])
    ]
    assert settled is not None and settled - ONSET <= 8, (
        f"settled at {settled}: {trace[ONSET - 2 : ONSET + 14]}; "
        f"true tau max {max((t['tau'] or 0) for t in truth):.3f} s over {len(truth)}"
    )
    assert _summary(log, "rejected values") == 1 and _summary(log, "future") == 1
    assert _summary(log, "foreign source") > 0 and _summary(log, "garbage") > 0
    assert sent["spoof"] > 50 and sent["flood"] > 500


def test_all_late_commands_are_noticed_and_the_estimate_stays_bounded(tmp_path: Path, gains_file: Path) -> None:
    port = free_udp_port()
    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        with monitor_daemon(tmp_path, gains_file, port, bus, "late") as monitor:
            wait_ready(monitor)
            with sim_daemon(
                tmp_path,
                port,
                bus,
                1,
                "--fault",
                f"bias:2@{ONSET}",
                "--delay",
                "const:1.2",
                steps=STEPS,
                speedup=SPEEDUP,
            ) as sim:
                assert sim.wait(60) == 0, sim.log()
            wait_for(lambda: len(estimates) >= STEPS, 30, what="estimates")
            assert monitor.stop() == 0
            log = monitor.log()
    # before the fault the commands are ~0 and so is the held deflection: indistinguishable, counted applied
    assert "not taking effect" in log and _summary(log, "not applied") >= STEPS - ONSET - 5
    assert all(abs(e["u"][0]) <= 30.0 for e in estimates)
    assert max(abs(e["f_hat"][0]) for e in estimates) < 10.0
    assert settling_k(estimates, 2.0, 0.1) is not None
    late = [e for e in estimates if e["k"] > ONSET + 6]
    assert late and all(e["commands_effective"] is False for e in late) and late[-1]["command_applied"] is False


def test_signed_frames_replayed_from_a_new_port_publish_nothing(tmp_path: Path, gains_file: Path) -> None:
    key = tmp_path / "key.hex"
    key.write_text(os.urandom(32).hex() + "\n")
    port = free_udp_port()
    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        with monitor_daemon(tmp_path, gains_file, port, bus, "signed", "--signing-key", str(key)) as monitor:
            wait_ready(monitor)
            with Relay(port) as relay:
                with sim_daemon(
                    tmp_path, relay.port, bus, 1, "--signing-key", str(key), steps=30, speedup=SPEEDUP
                ) as sim:
                    assert sim.wait(60) == 0, sim.log()
                captured = list(relay.captured)
            wait_for(lambda: len(estimates) >= 30, 30, what="signed estimates")
            before = len(estimates)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as replayer:
                for data in captured:
                    replayer.sendto(data, ("127.0.0.1", port))
            import time

            time.sleep(1.0)
            assert monitor.stop() == 0
            log = monitor.log()
    assert len(estimates) == before == 30
    assert _summary(log, "bad signature") >= len(captured) - 5, log[-1500:]
    assert processed_count(log) == 30
