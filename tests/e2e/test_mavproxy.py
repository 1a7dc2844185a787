"""MAVProxy, the router users put between vehicle and monitor, in the loop (one message per datagram).

Closed loop: sim-vehicle -> MAVProxy (udpin master, udpout to the monitor) -> fault-monitor run, and the
commands and ground-station feedback back the same way; MAVProxy's own tlog must hold all three. That way is the
README's block, run as it stands (``tests/readme_blocks.py``); the other way (MAVProxy listening for its outputs,
the monitor sending to it) is written out here.
Observe-only: the vehicle flies on its own gain (--autopilot), the monitor only watches, and the tlog
MAVProxy wrote during the live run, analysed offline, must give the same f_hat as the live monitor.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.daemons import Daemon, free_tcp_port, free_udp_port
from tests.e2e.mavproxy_router import MavProxy, tlog_counts
from tests.monitor_bus import processed_count, wait_ready
from tests.readme_blocks import Session, group

STEPS = 40
SPEEDUP = 10


def _wait_for_tlog(tlog: Path, timeout: float = 10.0) -> None:
    """MAVProxy writes its tlog from a queue on its own thread and a signal can end it before the queue drains:
    wait (bounded) until the tlog holds the vehicle's last sample before stopping it."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if tlog.exists() and tlog_counts(tlog)[("AOA_SSA", 1)] >= STEPS - 1:  # as the tests require
            return
        time.sleep(0.2)


def _vehicle(tmp_path: Path, port: int, *extra: str) -> Daemon:
    args = [
        "run",
        "--steps",
        str(STEPS),
        "--speedup",
        str(SPEEDUP),
        "--mavlink",
        f"udpout:127.0.0.1:{port}",
        "--no-zenoh",
        "--fault",
        "bias:2@20",
        "--summary-json",
        str(tmp_path / "vehicle.json"),
        *extra,
    ]
    return Daemon("sim_vehicle", args, tmp_path / "vehicle.log")


def _monitor(tmp_path: Path, gains: Path, port: int, *extra: str, kind: str = "udpin") -> Daemon:
    args = [
        "run",
        "--plant",
        "paper-continuous",
        "--gains",
        str(gains),
        "--mavlink",
        f"{kind}:127.0.0.1:{port}",
        "--zenoh-listen",
        f"tcp/127.0.0.1:{free_tcp_port()}",
        "--name",
        "behind-mavproxy",
        *extra,
    ]
    return Daemon("monitor", args, tmp_path / "monitor.log")


def _assert_closed_loop(monitor_log: str, applied: int, tlog: Path) -> None:
    assert processed_count(monitor_log) == STEPS, monitor_log[-2000:]
    assert applied >= 0.95 * STEPS, applied
    counts = tlog_counts(tlog)
    for telemetry in ("ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS"):
        assert counts[(telemetry, 1)] >= STEPS - 1, counts
    assert counts[("SET_ACTUATOR_CONTROL_TARGET", 255)] >= STEPS - 1, counts
    assert counts[("NAMED_VALUE_FLOAT:FHAT", 255)] >= STEPS - 1, counts
    assert counts[("STATUSTEXT", 255)] >= 1, counts  # the alarm on the 2-degree bias reached the GCS side


def test_the_readme_block_closes_the_loop_through_mavproxy(tmp_path: Path, gains_file: Path) -> None:
    """The README's block: the monitor listens (udpin), MAVProxy sends to it (--out=udpout)."""
    (block,) = group("mavproxy")
    with Session(tmp_path, steps=STEPS, speedup=SPEEDUP) as s:
        shutil.copy(gains_file, s.dir / "gains.toml")  # from the README's design line (run in tests/test_readme.py)
        monitor, _mavproxy, vehicle = s.run(block)
        _wait_for_tlog(s.dir / "flight.tlog")
        s.stop()
        s.assert_ran_all("mavproxy")
    applied = re.search(r"commands: received \d+, applied (\d+)", vehicle.out())
    assert applied, vehicle.failure("no summary")
    _assert_closed_loop(monitor.err(), int(applied.group(1)), s.dir / "flight.tlog")


def test_closed_loop_with_mavproxy_listening_for_its_outputs(tmp_path: Path, gains_file: Path) -> None:
    """Either side may listen: with MAVProxy's --out=udpin the monitor's HEARTBEAT is what opens the way back."""
    monitor_port, master_port = free_udp_port(), free_udp_port()
    with (
        MavProxy(tmp_path, master_port, monitor_port, "udpin") as mp,
        _monitor(tmp_path, gains_file, monitor_port, kind="udpout") as monitor,
    ):
        wait_ready(monitor)
        with _vehicle(tmp_path, master_port) as vehicle:
            assert vehicle.wait(60) == 0, vehicle.log()
        _wait_for_tlog(mp.tlog)
        mp.stop()
        assert monitor.stop() == 0
    summary = json.loads((tmp_path / "vehicle.json").read_text())
    _assert_closed_loop(monitor.log(), summary["commands"].get("applied", 0), mp.tlog)


def test_observe_only_live_and_from_mavproxys_tlog_agree(tmp_path: Path, gains_file: Path) -> None:
    from monitor.service.recording_reader import load_recording

    monitor_port, master_port = free_udp_port(), free_udp_port()
    live_rrd, offline_rrd = tmp_path / "live.rrd", tmp_path / "offline.rrd"
    with (
        _monitor(tmp_path, gains_file, monitor_port, "--observe", "--rrd", str(live_rrd)) as monitor,
        MavProxy(tmp_path, master_port, monitor_port) as mp,
    ):
        wait_ready(monitor)
        with _vehicle(tmp_path, master_port, "--autopilot", "-0.5") as vehicle:
            assert vehicle.wait(60) == 0, vehicle.log()
        _wait_for_tlog(mp.tlog)
        mp.stop()
        assert monitor.stop() == 0, monitor.log()[-2000:]
    log = monitor.log()
    assert processed_count(log) == STEPS and "commands 0" in log, log[-2000:]
    assert tlog_counts(mp.tlog)[("SET_ACTUATOR_CONTROL_TARGET", 255)] == 0
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "analyse",
            str(mp.tlog),
            "--plant",
            "paper-continuous",
            "--gains",
            str(gains_file),
            "--rrd",
            str(offline_rrd),
            "--json",
            "--fault",
            "bias:2@20",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["samples"] == STEPS and report["settling_steps"] is not None
    live = {s.k: s.f_hat[0] for s in load_recording(live_rrd).vehicles[1].samples}
    offline = {s.k: s.f_hat[0] for s in load_recording(offline_rrd).vehicles[1].samples}
    assert sorted(live) == sorted(offline) == list(range(STEPS))
    assert np.allclose([live[k] for k in live], [offline[k] for k in live], atol=1e-9)
    assert abs(live[STEPS - 1] - 2.0) < 0.2  # observe-only still finds the bias
