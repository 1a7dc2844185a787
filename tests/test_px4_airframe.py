"""The PX4 fixed-wing of docs/tutorials/px4.md: its signal map, as the page shows it, through ``identify``,
``design`` and ``analyse`` on JSBSim flights written as PX4 logs them (``tests/px4_flight.py``): a ULog with
PX4's topic names and rates, α derived from the NED velocity and the attitude quaternion."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from tests.px4_flight import PX4_TOPICS, T0_US, H, fly, write_px4_ulog
from tests.readme_blocks import file_block


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    work = tmp_path_factory.mktemp("px4")
    ident = fly(60.0, lead_in=5.0, seed=3, airspeed_kt=90.0)
    write_px4_ulog(work / "ident.ulg", ident, seed=1)
    faulty = fly(40.0, lead_in=5.0, seed=11, airspeed_kt=90.0, bias_deg=2.0, fault_at_s=20.0)
    write_px4_ulog(work / "faulty.ulg", faulty, seed=2)
    (work / "px4-fixed-wing.toml").write_text(file_block("px4-fixed-wing.toml").text)
    return {"work": work, "ident": ident, "faulty": faulty}


def test_the_written_ulog_is_one_pyulog_reads_with_px4_s_topics(logs) -> None:
    from pyulog import ULog

    ulog = ULog(str(logs["work"] / "ident.ulg"))
    n = len(logs["ident"])
    counts = {(d.name, d.multi_id): len(d.data["timestamp"]) for d in ulog.data_list}
    assert counts == {
        ("vehicle_angular_velocity", 0): n,
        ("vehicle_attitude", 0): n,
        ("vehicle_local_position", 0): n,
        ("actuator_servos", 0): n,
        ("actuator_outputs", 0): n // 5,
        ("actuator_outputs", 1): n // 5,
        ("airspeed_validated", 0): n // 10,
        ("wind", 0): n // 50,
    }
    assert {f.name for f in ulog.message_formats.values()} == set(PX4_TOPICS)
    att = ulog.get_dataset("vehicle_attitude").data
    assert np.allclose(np.hypot.reduce([att[f"q[{i}]"] for i in range(4)]), 1.0, atol=1e-6)
    assert not ulog.file_corruption and ulog.msg_info_dict["sys_name"] == "PX4"


def test_identify_design_analyse_on_a_px4_log(logs, capsys) -> None:
    work = logs["work"]
    plant, gains = work / "plane.toml", work / "gains.toml"
    argv = ["identify", str(work / "ident.ulg"), "--signals", str(work / "px4-fixed-wing.toml")]
    assert main([*argv, "--out", str(plant), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["samples"]["log"] == len(logs["ident"])
    assert report["h"] == pytest.approx(H, rel=1e-3)
    fits = report["fit_percent"]
    assert fits["alpha"] > 98 and fits["q"] > 98 and min(fits.values()) > 90, fits
    assert main(["design", "--plant", str(plant), "--out", str(gains)]) == 0
    capsys.readouterr()
    onset = round(T0_US / (H * 1e6)) + round(20.0 / H)
    code = main(
        ["analyse", str(work / "faulty.ulg"), "--plant", str(plant), "--gains", str(gains)]
        + ["--fault", f"bias:2@{onset}", "--json"]
    )
    out = capsys.readouterr().out
    assert code == 0
    result = json.loads(out)
    assert result["samples"] == len(logs["faulty"]) and result["log"]["inventory"]["kind"] == "ulog"
    assert result["false_alarms"] == 0 and 0 <= result["detection_steps"] <= 10, result
    f_hat = _f_hat_after(work / "faulty.ulg", plant, gains, result["k_first"])
    before, after = f_hat[250 : onset - result["k_first"]], f_hat[onset - result["k_first"] + 50 :]
    assert np.max(np.abs(before)) < 0.5 and abs(np.mean(after) - 2.0) < 0.1, (np.max(np.abs(before)), np.mean(after))


def _f_hat_after(log: Path, plant: Path, gains: Path, k0: int) -> np.ndarray:
    """f_hat of every sample from ``k0`` on, from the same observer analyse runs."""
    from monitor.link.onboard_log import open_onboard_log
    from monitor.service.alarm import AlarmConfig
    from monitor.service.fleet_file import Fleet, load_model
    from monitor.service.offline import analyse_dataflash

    ulog = open_onboard_log(log)
    fleet = Fleet(load_model(str(plant), gains, layouts=ulog.layouts))
    records = analyse_dataflash(ulog, fleet, AlarmConfig()).records
    return np.array([r.f_hat[0] for r in records if r.k >= k0])


def test_px4_s_default_logging_rates_take_the_default_logging_map(tmp_path: Path, capsys) -> None:
    """The same kind of flight at PX4's default logging rates (servos and velocity 10 Hz, attitude 25 Hz, out of
    phase): the high-rate map makes no sample and says which topics are slower than its instant; the page's
    default-logging map (the actuator's topic as instant, the rest latest values) identifies the short period."""
    flight = fly(60.0, lead_in=5.0, seed=3, airspeed_kt=90.0)
    log = tmp_path / "default.ulg"
    write_px4_ulog(log, flight, default_rates=True)
    for name in ("px4-fixed-wing.toml", "px4-fixed-wing-default-logging.toml"):
        (tmp_path / name).write_text(file_block(name).text)
    argv = ["identify", str(log), "--model", "short-period", "--out", str(tmp_path / "p.toml"), "--signals"]
    assert main([*argv, str(tmp_path / "px4-fixed-wing.toml")]) == 2
    err = capsys.readouterr().err
    slower = r"vehicle_local_position 9\.\d+ Hz, vehicle_attitude 2[\d.]+ Hz, actuator_servos 9\.\d+ Hz slower than"
    assert re.search(slower + r" the instant \(vehicle_angular_velocity [\d.]+ Hz\)", err), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert main([*argv, str(tmp_path / "px4-fixed-wing-default-logging.toml"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["h"] == pytest.approx(0.1, rel=1e-3)
    assert report["fit_percent"]["alpha"] > 80 and report["fit_percent"]["q"] > 70, report["fit_percent"]
