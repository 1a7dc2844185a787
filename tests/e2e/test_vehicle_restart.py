"""A vehicle restarted under the same sysid, against a real ``fault-monitor run`` daemon.

Why end to end: the defect lived between the link (a new source port), the pipeline (a HEARTBEAT never
reaches the vehicle table) and the table (which message decides a restart); only the daemon's own summary
and its recording, read back by ``fault-monitor replay``, show that the second run is answered and kept.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from monitor.model.plant import load_plant
from monitor.wire.mavlink import mavlink
from tests.daemons import REPO, free_udp_port
from tests.e2e.wire_peer import PeerVehicle, check_against_equations, fly_udp, read_gains
from tests.gains_files import hand_made_gains_file
from tests.monitor_bus import monitor_daemon, processed_count, sim_daemon, wait_ready, zenoh_bus

STEPS = 60  # samples per run
SILENCE_S = 1.6  # the monitor's restart_silence is 1 s
SYSID = 7


@pytest.fixture(scope="module")
def quick_gains(tmp_path_factory) -> Path:
    """Hand-made gains (no design: seconds saved); the restart logic does not depend on them."""
    return hand_made_gains_file(tmp_path_factory.mktemp("restart-gains") / "gains.toml")


class RestartedPeer(PeerVehicle):
    """A fresh vehicle process (k from 0) whose first datagram is a HEARTBEAT, then its timed parts with
    AOA_SSA (the instant) last: the order in which the restart used to be missed."""

    def frames(self, k: int) -> list[bytes]:
        out = super().frames(k)
        if k != 0:
            return out
        self.codec.send(
            mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_AUTOPILOT_GENERIC, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
            )
        )
        heartbeat = self.codec.file.take()
        return [heartbeat, *sorted(out, key=lambda frame: _msgid(frame) == mavlink.MAVLINK_MSG_ID_AOA_SSA)]


def _msgid(frame: bytes) -> int:
    """The message id of one MAVLink 2 frame (bytes 7-9, little-endian)."""
    return int.from_bytes(frame[7:10], "little")


def _replay(rrd: Path, sysid: int) -> dict:
    """``fault-monitor replay --json`` as a user runs it, for one vehicle."""
    done = subprocess.run(
        [sys.executable, "-m", "monitor", "replay", str(rrd), "--json", "--sysid", str(sysid)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _restarts(log: str) -> int:
    match = re.search(r"[ ,]restarts (\d+)", log.split("stopped:")[-1])
    assert match, log[-2000:]
    return int(match.group(1))


def test_a_pymavlink_vehicle_restarted_from_a_new_port_after_a_heartbeat(tmp_path: Path, quick_gains: Path) -> None:
    plant = load_plant("paper-continuous")
    first = PeerVehicle(plant, SYSID, seed=1, fault_at=40)  # the old run ends with a non-zero estimate
    second = RestartedPeer(plant, SYSID, seed=2, bias=0.0)  # a fresh estimator answers it with exact zeros
    port, rrd = free_udp_port(), tmp_path / "restart.rrd"
    with zenoh_bus() as bus:
        with monitor_daemon(tmp_path, quick_gains, port, bus, "restart", "--rrd", str(rrd)) as monitor:
            wait_ready(monitor)
            fly_udp(first, port, STEPS)
            time.sleep(SILENCE_S)
            fly_udp(second, port, STEPS)  # its own socket: a new source port
            assert monitor.stop() == 0, monitor.log()[-3000:]
            log = monitor.log()
    processed = processed_count(log)
    assert processed >= 110 and _restarts(log) == 1 and "restarted (new source" in log, log[-3000:]
    assert sorted(second.wire.commands) == list(range(STEPS))  # every sample of the new run was answered
    gains = read_gains(quick_gains)
    assert check_against_equations(plant, gains, second.wire, list(range(STEPS))) == STEPS  # from a fresh state
    report = _replay(rrd, SYSID)
    assert report["runs"] == 2 and report["samples"] >= 110 and report["last_run_samples"] >= 55, report
    print(
        f"pymavlink restart: processed {processed}/{2 * STEPS}, replay runs {report['runs']}, "
        f"samples {report['samples']}"
    )


def test_sim_vehicle_restarted_under_the_same_sysid(tmp_path: Path, quick_gains: Path) -> None:
    """Two ``sim-vehicle`` processes one after the other (ATTITUDE first in each datagram, a new port)."""
    port, rrd = free_udp_port(), tmp_path / "sim-restart.rrd"
    with zenoh_bus() as bus:
        with monitor_daemon(tmp_path, quick_gains, port, bus, "sim-restart", "--rrd", str(rrd)) as monitor:
            wait_ready(monitor)
            for run in range(2):
                time.sleep(SILENCE_S if run else 0.0)
                where = tmp_path / f"sim-run{run}"  # each process its own log
                where.mkdir()
                with sim_daemon(where, port, bus, SYSID, steps=STEPS, speedup=50) as sim:
                    assert sim.wait(30) == 0, sim.log()[-2000:]
            assert monitor.stop() == 0, monitor.log()[-3000:]
            log = monitor.log()
    processed = processed_count(log)
    assert processed >= 110 and _restarts(log) == 1, log[-3000:]
    report = _replay(rrd, SYSID)
    assert report["runs"] == 2 and report["samples"] >= 110, report
    print(
        f"sim-vehicle restart: processed {processed}/{2 * STEPS}, replay runs {report['runs']}, "
        f"samples {report['samples']}"
    )
