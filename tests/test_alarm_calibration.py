"""``--alarm-threshold auto --turbulence LEVEL --calibration-log LOG``: the Gaussian threshold checked against
fault-free flights whose f_hat has heavier tails than the linear model's, written as tlogs the way MAVProxy writes
them (a flight sim-vehicle never flew: the paper's plant driven by a gust with Student-t increments)."""

from __future__ import annotations

import logging
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from monitor.checks.calibration import crossing_rates
from monitor.checks.detectability import turbulence_threshold
from monitor.commands.alarm_calibration import calibrate_on_logs
from monitor.model.plant import load_plant
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.offline import analyse_log
from monitor.wire.mavlink import mavlink, new_codec

PRESET = Path(__file__).resolve().parents[1] / "monitor" / "presets" / "paper-continuous.toml"
SIGMA, TIME_CONSTANT = 0.02, 3.0  # the [disturbance] the plant file states (deg, s)
HOURS = 2.0


def _plant_file(tmp: Path) -> Path:
    path = tmp / "plant.toml"
    text = PRESET.read_text("utf-8")
    path.write_text(
        text + f'\n[disturbance]\nsigma = {SIGMA}\ntime_constant = {TIME_CONSTANT}\nturbulence = "light"\n', "utf-8"
    )
    return path


def _write_flight(path: Path, plant, seed: int) -> None:
    """``HOURS`` of observe-only flight (u = -0.5 y) in a Gauss-Markov gust of the stated sigma and time constant
    whose increments are Student-t with 3 degrees of freedom (scaled to the same variance): heavy tails."""
    rng = np.random.default_rng(seed)
    n = int(HOURS * 3600 / plant.h)
    a = np.exp(-plant.h / TIME_CONSTANT)
    shocks = rng.standard_t(3, size=n) / np.sqrt(3.0)  # unit variance
    codec = new_codec(3, 1)
    x, u_prev, d = np.zeros(plant.n), 0.0, 0.0
    t0 = 1_700_000_000_000_000
    with open(path, "wb") as fh:
        for k in range(n):
            y = float((plant.C @ x)[0])
            u = -0.5 * y
            t_us = 5_000_000 + k * int(plant.h * 1e6)
            for i, m in enumerate(
                (
                    mavlink.MAVLink_attitude_message((t_us // 1000) & 0xFFFFFFFF, 0, 0, 0, 0, x[1] / 57.3, 0),
                    mavlink.MAVLink_aoa_ssa_message(t_us, y, 0.0),
                    mavlink.MAVLink_actuator_output_status_message(t_us, 1, [u] + [0.0] * 31),
                )
            ):
                codec.send(m)
                fh.write(struct.pack(">Q", t0 + k * 1_000_000 + i * 1000) + codec.file.take())
            d = a * d + SIGMA * np.sqrt(1 - a * a) * shocks[k]
            x = plant.A @ x + (plant.B0 * u + plant.B1 * u_prev + plant.Dd * d).ravel()
            u_prev = u


@pytest.fixture(scope="module")
def flights(tmp_path_factory) -> dict:
    from monitor.design.result import DesignResult
    from monitor.gains import write_gains
    from monitor.model.closed_loop import Gains

    tmp = tmp_path_factory.mktemp("calibration")
    plant_path = _plant_file(tmp)
    p = load_plant(plant_path)
    cdf = float((p.C @ p.Df)[0, 0])  # the fault-direction deadbeat observer: f_hat follows the gust at once
    zero = np.zeros((1, 1))
    g = Gains(L=(p.A + np.eye(2)) @ p.Df / cdf, M=np.array([[1.0 / cdf]]), K1=zero, K2=zero, K3=zero)
    gains = tmp / "gains.toml"
    write_gains(gains, DesignResult("deadbeat", g, 0.0, 0.0, 0.0, 0.0, 0.0), p)
    logs = [tmp / "calibration.tlog", tmp / "check.tlog"]
    for seed, log in enumerate(logs):
        _write_flight(log, p, seed)
    return {"plant": plant_path, "gains": gains, "logs": logs, "model": load_model(str(plant_path), str(gains))}


def _fhat(log: Path, model) -> np.ndarray:
    records = analyse_log(log, Fleet(model), AlarmConfig()).records
    return np.array([r.f_hat[0] for r in records])


def test_a_heavy_tailed_flight_raises_the_threshold_to_where_another_flight_keeps_the_budget(flights) -> None:
    """The Gaussian threshold is crossed far more than once an hour by a flight with heavy-tailed gusts; the
    threshold calibrated on one such flight is crossed at most a few times an hour by another (a different seed),
    and never below the Gaussian one."""
    model = flights["model"]
    gaussian = turbulence_threshold(model.plant, model.gains.gains, "light")
    threshold, calibration = calibrate_on_logs([str(flights["logs"][0])], Fleet(model), gaussian, 1.0)
    assert calibration is not None and calibration.kept in ("gaussian", "exponential")
    assert threshold == calibration.threshold > gaussian
    check = _fhat(flights["logs"][1], model)
    _n, (at_gaussian, at_calibrated), hours = crossing_rates([check], np.array([gaussian, threshold]), model.plant.h)
    print(f"gaussian {gaussian:.4g}: {at_gaussian:.1f}/h; calibrated {threshold:.4g}: {at_calibrated:.1f}/h")
    assert hours == pytest.approx(HOURS, rel=0.01)
    assert at_gaussian > 4.0 and at_calibrated <= 3.0


def test_the_cli_takes_it_with_auto_and_turbulence_only_and_says_what_it_did(flights, caplog) -> None:
    base = ["analyse", str(flights["logs"][1]), "--plant", str(flights["plant"]), "--gains", str(flights["gains"])]
    log = str(flights["logs"][0])
    for extra, message in (
        (["--calibration-log", log], "--calibration-log applies to --alarm-threshold auto --turbulence LEVEL"),
        (["--alarm-threshold", "auto", "--disturbance-bound", "1", "--calibration-log", log], "applies to"),
        (["--alarm-threshold", "auto", "--turbulence", "light", "--calibration-log", "none.tlog"], "no such log"),
    ):
        done = subprocess.run([sys.executable, "-m", "monitor", *base, *extra], capture_output=True, text=True)
        assert done.returncode == 2 and message in done.stderr and len(done.stderr.strip().splitlines()) == 1
    from monitor.cli import main

    with caplog.at_level(logging.INFO, logger="monitor.alarm"):
        code = main([*base, "--alarm-threshold", "auto", "--turbulence", "light", "--calibration-log", log])
    assert code == 0
    assert any("calibrated on 120.0 min of flight" in r.getMessage() for r in caplog.records)
