"""`fault-monitor demo` end to end in a reduced form: real daemons, real Zenoh, real recordings, real PNGs."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from monitor.scoring import score_recording
from monitor.service.recording_reader import load_recording


def demo(out, *args: str, timeout: float = 150) -> dict:
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "demo", "--out", str(out), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert ("FE settling" in proc.stdout) or ("Monte-Carlo over" in proc.stdout)
    return json.loads((out / ("montecarlo.json" if "--runs" in args else "summary.json")).read_text())


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    return tmp_path_factory.mktemp("demo")


def test_live_demo_table_comes_from_the_run(out):
    first = demo(out, "--methods", "certified", "--steps", "40", "--speedup", "20", "--fault", "bias:2@10")
    row = first["rows"][0]
    assert row["method"] == "certified" and row["stable"] and row["certificate"] == "valid"
    assert row["samples"] >= 38
    rrd = out / "certified.rrd"
    report = score_recording(load_recording(rrd), fault_spec="bias:2@10")
    assert report["samples"] == row["samples"] and report["settling_steps"] == row["settling_steps"]
    assert report["rms_ef_after_onset"] == pytest.approx(row["rms_ef"])
    assert row["settling_steps"] is not None and 2 <= row["settling_steps"] <= 10
    assert row["alarm_delay"] is not None and row["false_alarms"] == 0
    for name in ("fig3_fault_estimate.png", "fig4_alpha.png", "fig5_q.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert "cached" not in (out / "gains" / "certified.toml").read_text()  # a real gains file, reused below
    monitor_log = (out / "logs" / "certified-monitor.log").read_text()
    assert " INFO " in monitor_log and "ready:" in monitor_log and "alarm raised" in monitor_log
    assert " INFO " in (out / "logs" / "certified-sim.log").read_text()

    # the vehicle flew the fault asked for, not the demo's default (bias:2@20): the recorded truth says so
    (series,) = load_recording(rrd).vehicles.values()
    assert min(t.k for t in series.truth if t.f and t.f[0] != 0.0) == 10


def test_monte_carlo_mode_depends_on_the_seed_and_keeps_the_live_summary(out):
    live_summary = (out / "summary.json").read_bytes()  # written by the live test above
    a = demo(out, "--methods", "certified,separate", "--runs", "4", "--steps", "60", "--seed", "1")
    b = demo(out, "--methods", "certified", "--runs", "4", "--steps", "60", "--seed", "7")
    ra, rb = a["results"]["certified"], b["results"]["certified"]
    assert a["mode"] == "monte-carlo" and ra["runs"] == 4 and ra["settled_runs"] == 4
    assert ra["settling_mean"] >= 2  # never before the 2-sample floor
    assert ra["rms_ef_mean"] != rb["rms_ef_mean"]
    assert (out / "summary.json").read_bytes() == live_summary  # Monte-Carlo has its own file
    # the unstable design swings between the elevator limits, as on the live vehicle: alpha stays bounded
    assert not a["results"]["separate"]["stable"] and a["results"]["separate"]["peak_alpha_worst"] < 30


@pytest.mark.not_paced  # refusals: no loop
def test_bad_options_are_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "demo", "--out", str(tmp_path), "--methods", "magic"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "magic" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "demo", "--out", str(tmp_path), "--fault", "bias:x@y"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "bias:x@y" in proc.stderr and "Traceback" not in proc.stderr
