"""Recordings keep a restarted vehicle's runs apart, and a recording that cannot be written says so at once."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import pytest

from monitor.scoring import score_recording
from monitor.service.recorder import RrdRecorder
from monitor.service.recording_reader import load_recording
from monitor.service.records import SampleRecord


def _record(k: int, run: int, wall: float) -> SampleRecord:
    return SampleRecord(
        sysid=1,
        k=k,
        t=float(k),
        wall=wall,
        y=[0.1],
        alpha=0.1,
        q=0.0,
        elevator=None,
        x_hat=[0.0, 0.0],
        f_hat=[0.01 * k],
        u=[0.0],
        residual=[0.0],
        tau_obs=None,
        processing_s=1e-5,
        alarm=False,
        run=run,
    )


def test_a_restarted_vehicle_keeps_both_runs(tmp_path: Path) -> None:
    path = tmp_path / "restart.rrd"
    wall = time.time()
    with RrdRecorder(path) as rec:
        for k in range(50):
            rec.submit(_record(k, 0, wall + k * 0.01))
        for k in range(30):  # the vehicle process restarted: k starts again
            rec.submit(_record(k, 1, wall + 1.0 + k * 0.01))
    recording = load_recording(path)
    samples = recording.vehicles[1].samples
    assert len(samples) == 80 and [s.run for s in samples] == [0] * 50 + [1] * 30
    report = score_recording(recording)
    assert report["samples"] == 80 and report["runs"] == 2 and report["last_run_samples"] == 30


@pytest.fixture
def tiny_disk(tmp_path: Path):
    mount = tmp_path / "tiny"
    mount.mkdir()
    if (
        os.geteuid() != 0
        or subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=48k", "tmpfs", str(mount)], capture_output=True
        ).returncode
        != 0
    ):
        pytest.skip("needs root to mount a tiny tmpfs (CI and the developers' machines are root)")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def test_a_full_disk_is_an_error_while_running_not_only_at_close(tiny_disk: Path) -> None:
    rec = RrdRecorder(tiny_disk / "run.rrd", max_age_s=0.05, poll_s=0.01)
    wall = time.time()
    deadline = time.monotonic() + 20
    k = 0
    while rec.error is None and time.monotonic() < deadline:
        for _ in range(200):
            rec.submit(_record(k, 0, wall + k * 0.01))
            k += 1
        time.sleep(0.1)
    assert rec.error is not None and "disk full" in rec.error, (rec.error, k)
    rec.close()
    assert rec.stats["failed"] > 0


def test_the_daemon_reports_a_failing_recording_in_its_status_and_exit_code(tiny_disk: Path, tmp_path: Path) -> None:
    from tests.daemons import free_udp_port, wait_for
    from tests.gains_files import hand_made_gains_file
    from tests.monitor_bus import monitor_daemon, sim_daemon, zenoh_bus

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    port = free_udp_port()
    with zenoh_bus() as bus:
        with monitor_daemon(tmp_path, gains, port, bus, "fulldisk", "--rrd", str(tiny_disk / "run.rrd")) as monitor:
            wait_for(lambda: "ready:" in monitor.log(), 20, what="monitor ready")
            with sim_daemon(tmp_path, port, bus, 1, steps=400, speedup=100) as sim:
                assert sim.wait(60) == 0
            wait_for(lambda: "disk full" in monitor.log(), 10, what="the recording error")
            wait_for(
                lambda: any("recording_error" in p for _, p in bus.query("uav/1/fault/status")),
                10,
                what="recording_error in the status",
            )
            assert monitor.stop(timeout=30) == 1  # closing a file on a full disk may take the recorder's 10-s wait
            log = monitor.log()
    error_line = next(line for line in log.splitlines() if "disk full" in line)
    assert " ERROR " in error_line and log.index(error_line) < log.index("stopped:")
