"""``fault-monitor analyse``: a tlog of a flight sim-vehicle never flew, checked against eq. (5) by hand."""

from __future__ import annotations

import json
import random
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from monitor.link.signals import default_signal_map
from monitor.model.plant import load_plant
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.offline import analyse_log
from monitor.wire.mavlink import mavlink, new_codec
from tests.e2e.wire_peer import read_gains

STEPS = 120
ONSET = 40


def _write_flight(path: Path, plant, seed: int = 0, garbage: bool = True) -> dict[int, tuple[float, float]]:
    """An autopilot-flown flight (u(k) = -0.5 y(k)), one message per record in MAVProxy's format.

    Returns k -> (y, u) as float32 values on the wire. Records are shuffled within a sample, HEARTBEATs
    and a VFR_HUD are mixed in, and (``garbage``) a few damaged bytes sit between records.
    """
    rng = random.Random(seed)
    codec = new_codec(3, 1)
    x, u_prev = np.zeros(plant.n), 0.0
    wire: dict[int, tuple[float, float]] = {}
    t0 = 1_700_000_000_000_000
    with open(path, "wb") as fh:
        for k in range(STEPS):
            y = float((plant.C @ x)[0])
            u = -0.5 * y
            t_us = 5_000_000 + k * int(plant.h * 1e6)
            msgs = [
                mavlink.MAVLink_attitude_message((t_us // 1000) & 0xFFFFFFFF, 0, 0, 0, 0, x[1] / 57.3, 0),
                mavlink.MAVLink_aoa_ssa_message(t_us, y, 0.0),
                mavlink.MAVLink_actuator_output_status_message(t_us, 1, [u] + [0.0] * 31),
                mavlink.MAVLink_vfr_hud_message(20.0, 20.0, 0, 50, 100.0, 0.0),
            ]
            if k % 10 == 0:
                msgs.append(mavlink.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3))
            rng.shuffle(msgs)
            for i, m in enumerate(msgs):
                codec.send(m)
                fh.write(struct.pack(">Q", t0 + k * 1_000_000 + i * 1000) + codec.file.take())
            if garbage and k == 50:
                fh.write(b"\x00\x01garbage\xfd")
            wire[k] = (float(np.float32(y)), float(np.float32(u)))
            f = 2.0 if k >= ONSET else 0.0
            x = plant.A @ x + (plant.B0 * u + plant.B1 * u_prev + plant.Df * f).ravel()
            u_prev = u
    return wire


@pytest.fixture(scope="module")
def gains(tmp_path_factory) -> Path:
    """The fault-direction deadbeat observer (L = (A+I) Df / (C Df), M = 1 / (C Df)): observe-only needs no K."""
    from monitor.design.result import DesignResult
    from monitor.gains import write_gains
    from monitor.model.closed_loop import Gains

    p = load_plant("paper-continuous")
    cdf = float((p.C @ p.Df)[0, 0])
    g = Gains(
        L=(p.A + np.eye(2)) @ p.Df / cdf,
        M=np.array([[1.0 / cdf]]),
        K1=np.zeros((1, 1)),
        K2=np.zeros((1, 1)),
        K3=np.zeros((1, 1)),
    )
    path = tmp_path_factory.mktemp("g") / "gains.toml"
    write_gains(
        path,
        DesignResult(
            method="deadbeat", gains=g, gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0
        ),
        p,
    )
    return path


def test_analyse_runs_eq5_on_what_the_log_holds(tmp_path: Path, gains: Path) -> None:
    plant = load_plant("paper-continuous")
    tlog = tmp_path / "flight.tlog"
    wire = _write_flight(tmp_path / "flight.tlog", plant)
    result = analyse_log(tlog, Fleet(load_model("paper-continuous", gains)), AlarmConfig())
    assert [r.k for r in result.records] == list(range(5, 5 + STEPS))  # k = time_usec / h: the vehicle's epoch
    assert result.skipped_bytes > 0 and result.counts["foreign"] > 0 and result.counts["heartbeats"] == 12
    g = read_gains(gains)
    xh, fh, u_prev = np.zeros(2), np.zeros(1), np.zeros(1)
    for record in result.records:
        y, u = wire[record.k - 5]
        assert record.f_hat[0] == pytest.approx(fh[0], abs=1e-9) and record.u[0] == pytest.approx(u)
        r = np.array([y]) - plant.C @ xh
        xh = plant.A @ xh + plant.B0 @ [u] + plant.B1 @ u_prev + plant.Df @ fh + g["L"] @ r
        fh, u_prev = fh + g["M"] @ r, np.array([u])
    assert abs(result.records[-1].f_hat[0] - 2.0) < 0.05  # observe-only finds the bias the autopilot flew with


def test_analyse_command_report_json_and_rrd(tmp_path: Path, gains: Path) -> None:
    plant = load_plant("paper-continuous")
    tlog = tmp_path / "flight.tlog"
    _write_flight(tlog, plant, garbage=False)
    rrd = tmp_path / "flight.rrd"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "analyse",
            str(tlog),
            "--plant",
            "paper-continuous",
            "--gains",
            str(gains),
            "--json",
            "--rrd",
            str(rrd),
            "--fault",
            f"bias:2@{ONSET + 5}",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["samples"] == STEPS and report["onset_k"] == ONSET + 5 and report["log"]["processed"] == STEPS
    from monitor.scoring import score_recording
    from monitor.service.recording_reader import load_recording

    again = score_recording(load_recording(rrd), fault_spec=f"bias:2@{ONSET + 5}")
    assert again["samples"] == STEPS and again["rms_ef"] == pytest.approx(report["rms_ef"])


def test_analyse_with_the_proven_alarm_threshold(tmp_path: Path, gains: Path) -> None:
    """--alarm-threshold auto: far below the default 1.0, yet the wind alone never trips it; the fault does."""
    tlog = tmp_path / "flight.tlog"
    _write_flight(tlog, load_plant("paper-continuous"), garbage=False)
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "analyse",
            str(tlog),
            "--plant",
            "paper-continuous",
            "--gains",
            str(gains),
            "--json",
            "--fault",
            f"bias:2@{ONSET + 5}",
            "--alarm-threshold",
            "auto",
            "--disturbance-bound",
            "0.002",
            "--log-level",
            "info",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["false_alarms"] == 0 and report["detection_steps"] is not None
    assert "alarm threshold auto" in out.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.tlog"], "no such log file"),
        (["{tlog}", "--sysid", "300"], "--sysid must be"),
        (["{tlog}", "--sysid", "7"], "no sample could be assembled"),
        (["{tlog}", "--fault", "bias:x@1"], "bias"),
        (["{tlog}", "--signals", "{bad}"], "unknown MAVLink message 'NOPE'"),
        (["{tlog}", "--alarm-threshold", "auto"], "needs --disturbance-bound"),
    ],
)
def test_analyse_bad_input_is_one_line_exit_2(tmp_path: Path, gains: Path, args: list[str], message: str) -> None:
    tlog = tmp_path / "flight.tlog"
    _write_flight(tlog, load_plant("paper-continuous"))
    bad = tmp_path / "signals.toml"
    bad.write_text(
        '[signals]\ninstant = "AOA_SSA"\noutputs = ["a"]\nactuator = ["e"]\n[signals.measured]\n'
        'a = { field = "NOPE.x" }\ne = { field = "ACTUATOR_OUTPUT_STATUS.actuator[0]" }\n'
    )
    argv = [a.format(tlog=tlog, bad=bad) for a in args]
    out = subprocess.run(
        [sys.executable, "-m", "monitor", "analyse", *argv, "--plant", "paper-continuous", "--gains", str(gains)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert out.returncode == 2 and message in out.stderr, out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert default_signal_map().instant == "AOA_SSA"
