"""What a log holds (``monitor/link/log_inventory.py``), and what ``analyse`` says about a MAVLink 1 log.

The log is what an ArduCopter 3.2 on a MAVLink 1 telemetry radio leaves in a ground station's tlog: HEARTBEAT,
ATTITUDE, SERVO_OUTPUT_RAW, VFR_HUD and RAW_IMU in MAVLink 1 (no AOA_SSA or ACTUATOR_OUTPUT_STATUS: ids above
255 do not exist in v1), plus the ground station's own MAVLink 2 heartbeats (sysid 255).
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import pytest

from monitor.cli import main
from monitor.link.log_inventory import explain_missing, read_inventory
from monitor.link.signals import default_signal_map
from monitor.wire.mavlink import mavlink, new_codec
from tests.mavlink1_signals import V1_SIGNALS

V1_MAP = V1_SIGNALS  # one map of a MAVLink 1 log's own messages for both test modules
T0_US = 1_700_000_000_000_000


def write_v1_log(path: Path, seconds: int = 40, h: float = 1.0) -> None:
    """Per second: ATTITUDE and SERVO_OUTPUT_RAW (one sample, h = 1 s), RAW_IMU, VFR_HUD and a HEARTBEAT, all
    MAVLink 1 from sysid 1; a MAVLink 2 HEARTBEAT from the ground station (sysid 255) every 2 s."""
    from pymavlink.dialects.v10 import ardupilotmega as v1

    vehicle = v1.MAVLink(None, srcSystem=1, srcComponent=1)
    gcs = new_codec(255, 190)
    with open(path, "wb") as fh:

        def record(t_us: int, frame: bytes) -> None:
            fh.write(struct.pack(">Q", T0_US + t_us) + frame)

        for k in range(int(seconds / h)):
            t_us = 7_000_000 + int(k * h * 1e6)
            alpha = 2.0 * math.sin(0.3 * k)
            record(
                t_us,
                v1.MAVLink_attitude_message(t_us // 1000, 0.0, math.radians(alpha), 0.0, 0.0, 0.0, 0.0).pack(vehicle),
            )
            record(
                t_us + 1000,
                v1.MAVLink_servo_output_raw_message(t_us, 0, 1500, 1500 + 5 * k % 40, 1000, 1500, 0, 0, 0, 0).pack(
                    vehicle
                ),
            )
            record(t_us + 2000, v1.MAVLink_raw_imu_message(t_us, 0, 0, -1000, 0, 0, 0, 0, 0, 0).pack(vehicle))
            record(t_us + 3000, v1.MAVLink_vfr_hud_message(15.0, 15.0, 0, 40, 100.0, 0.0).pack(vehicle))
            record(t_us + 4000, v1.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(vehicle))
            if k % 2 == 0:
                gcs.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
                record(t_us + 5000, gcs.file.take())


def test_the_inventory_counts_versions_messages_rates_and_sysids(tmp_path: Path) -> None:
    log = tmp_path / "copter32.tlog"
    write_v1_log(log, seconds=40)
    inv = read_inventory(log)
    assert inv.records == 220 and inv.frames_v1 == 200 and inv.frames_v2 == 20
    assert inv.sysids() == {1: 200, 255: 20}
    rates = {m.name: inv.rate_hz(m.count) for m in inv.messages()}
    assert rates["ATTITUDE"] == pytest.approx(40 / 39.0, rel=1e-3)  # 40 over the first-to-last 39 s span
    assert rates["HEARTBEAT"] == pytest.approx(60 / 39.0, rel=1e-3)
    assert {m.name: m.sysids for m in inv.messages()}["HEARTBEAT"] == {1, 255}
    lines = inv.lines()
    assert lines[0] == "220 records over 39.0 s, 220 frames (MAVLink 1: 200, MAVLink 2: 20)"
    assert "1 (200 frames), 255 (20 frames)" in lines[1] and "ATTITUDE 1.03 Hz" in lines[2]
    block = inv.as_dict()
    assert block["frames_v1"] == 200 and {m["name"] for m in block["messages"]} >= {"SERVO_OUTPUT_RAW", "RAW_IMU"}
    # the default map's messages are not in a v1 log: named, with the log's messages that could carry them
    smap = default_signal_map()
    line = explain_missing(inv, smap, ("alpha", "elevator"), sysid=1)
    assert line.startswith(
        "missing signals: alpha (AOA_SSA.AOA), elevator (ACTUATOR_OUTPUT_STATUS.actuator[0]): "
        "the log has no ACTUATOR_OUTPUT_STATUS or AOA_SSA from sysid 1"
    ), line
    assert line.endswith(
        "; what the log has instead: angle of attack: none; actuator output: SERVO_OUTPUT_RAW 1.03 Hz; "
        "the instant (time_usec): RAW_IMU, SERVO_OUTPUT_RAW"
    ), line
    assert "system ids are 1, 255" in explain_missing(inv, smap, ("alpha",), sysid=7)


def test_analyse_says_what_a_mavlink1_log_holds_and_reads_it_with_its_own_messages(tmp_path: Path, capsys) -> None:
    from tests.gains_files import hand_made_gains_file

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    log = tmp_path / "copter32.tlog"
    write_v1_log(log, seconds=40)
    code = main(["analyse", str(log), "--plant", "paper-continuous", "--gains", str(gains)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "no sample could be assembled from 220 log records (200 MAVLink 1 and 20 MAVLink 2 frames" in err[0]
    assert "missing signals: alpha (AOA_SSA.AOA), elevator (ACTUATOR_OUTPUT_STATUS.actuator[0])" in err[0]
    assert "actuator output: SERVO_OUTPUT_RAW" in err[0]
    signals = tmp_path / "v1.toml"
    signals.write_text(V1_MAP)
    code = main(["analyse", str(log), "--plant", "paper-continuous", "--gains", str(gains), "--signals", str(signals)])
    out = capsys.readouterr().out
    assert code == 0 and "log holds: 220 records over 39.0 s, 220 frames (MAVLink 1: 200, MAVLink 2: 20)" in out
    assert "log holds: system ids 1 (200 frames), 255 (20 frames)" in out
    code = main(
        ["analyse", str(log), "--plant", "paper-continuous", "--gains", str(gains), "--signals", str(signals), "--json"]
    )
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["samples"] == 40 and report["log"]["frames_v1"] == 200
    inv = report["log"]["inventory"]
    assert inv["frames_v1"] == 200 and inv["frames_v2"] == 20 and inv["sysids"] == {"1": 200, "255": 20}
    hz = {m["name"]: m["hz"] for m in inv["messages"]}
    assert hz["SERVO_OUTPUT_RAW"] == pytest.approx(1.026, abs=1e-3)
