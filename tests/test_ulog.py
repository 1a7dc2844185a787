"""PX4 ULog logs (``monitor/link/ulog.py``), read as they are: two of pyulog's own sample logs (tests/data/ulog,
real flights nobody here wrote; see tests/data/ulog/README.md), with hand-written signal maps.

What is checked against pyulog itself: the inventory (``log holds:``) against ``ulog_info``'s table, and every
assembled sample's values against the topic's own arrays at the instant's timestamp.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.errors import UserError
from monitor.link.flight_log import log_spacing, read_flight
from monitor.link.onboard_log import open_onboard_log
from monitor.link.signals import parse_signals

DATA = Path(__file__).parent / "data" / "ulog"
SMALL = DATA / "sample_log_small.ulg"  # PX4 v1.11 (CubeOrange), a system-identification logging profile
APPENDED = DATA / "sample_appended_multiple.ulg"  # PX4 v1.7 (Pixhawk 4 Pro), crash dump appended
RAD = 57.29577951308232

RATE_MAP = """
[signals]
instant = "vehicle_angular_velocity"
outputs = ["q"]
actuator = ["pitch_control"]
[signals.measured]
q = { field = "vehicle_angular_velocity.xyz[1]", scale = 57.29577951308232, unit = "deg/s" }
pitch_control = { field = "actuator_controls_0.control[1]", unit = "1" }
attitude_x = { field = "vehicle_attitude.q[1]", hold = 0.1 }
servo_3 = { field = "actuator_outputs[1].output[2]", hold = 1.0, unit = "us" }
"""


def _map(text: str, log, outputs: int = 1, inputs: int = 1):
    return parse_signals(tomllib.loads(text)["signals"], "test map", outputs, inputs, log.layouts)


def _ulog_info(path: Path) -> tuple[dict[str, int], str]:
    """``ulog_info``'s table: 'name (multi id, size)  count  bytes' -> {topic as a signal map names it: count};
    and its whole output."""
    script = Path(sys.executable).parent / "ulog_info"
    out = subprocess.run([str(script), str(path)], capture_output=True, text=True, timeout=60, check=True).stdout
    rows = {}
    for m in re.finditer(r"^ (\w+) \((\d+), \d+\)\s+(\d+)\s+\d+$", out, re.M):
        name, multi_id, count = m.group(1), int(m.group(2)), int(m.group(3))
        rows[name if multi_id == 0 else f"{name}[{multi_id}]"] = count
    assert rows, out
    return rows, out


@pytest.mark.parametrize("path", [SMALL, APPENDED], ids=lambda p: p.name)
def test_the_inventory_is_what_ulog_info_says(path: Path) -> None:
    log = open_onboard_log(path)
    assert log is not None and log.kind == "ulog"
    inv = log.inventory.as_dict()
    ours = {m["name"]: m["count"] for m in inv["messages"]}
    rows, info = _ulog_info(path)
    assert ours == {k: v for k, v in rows.items() if v}
    from pyulog import ULog

    ulog = ULog(str(path))
    assert inv["dropouts"] == len(ulog.dropouts)
    assert inv["first_us"] == ulog.start_timestamp and inv["last_us"] == ulog.last_timestamp
    duration = re.search(r"duration: (\d+):(\d\d):(\d\d)", info)
    assert duration and int(inv["span_s"]) == 3600 * int(duration[1]) + 60 * int(duration[2]) + int(duration[3])
    assert inv["records"] == sum(ours.values())


def test_a_hand_written_map_reads_the_topics_at_their_own_timestamps() -> None:
    """Every sample's q is vehicle_angular_velocity.xyz[1] at the instant's timestamp; the control is
    actuator_controls_0's record of the same cycle; the held attitude is the newest at or before the instant."""
    log = open_onboard_log(SMALL)
    smap = _map(RATE_MAP, log)
    h = log_spacing(str(SMALL), smap.instant, None, dataflash=log)
    assert h is not None
    flight = read_flight(str(SMALL), smap, h, dataflash=log)
    rows = flight.samples[1]
    from pyulog import ULog

    ulog = ULog(str(SMALL))
    gyro = ulog.get_dataset("vehicle_angular_velocity").data
    ctrl = ulog.get_dataset("actuator_controls_0").data
    att = ulog.get_dataset("vehicle_attitude").data
    out1 = ulog.get_dataset("actuator_outputs", 1).data
    assert len(rows) > 0.9 * len(gyro["timestamp"]), (len(rows), flight.counters)
    by_q = {round(float(v) * RAD, 9): int(t) for v, t in zip(gyro["xyz[1]"], gyro["timestamp"], strict=True)}
    checked = 0
    for _k, values in rows[:: max(len(rows) // 200, 1)]:
        t = by_q[round(values["q"], 9)]
        i = int(np.argmin(np.abs(ctrl["timestamp"].astype(np.int64) - t)))
        assert values["pitch_control"] == pytest.approx(float(ctrl["control[1]"][i]))
        j = int(np.searchsorted(att["timestamp"], t, side="right")) - 1
        if j >= 0 and t - int(att["timestamp"][j]) <= 100_000:
            assert values["attitude_x"] == pytest.approx(float(att["q[1]"][j]))
        checked += 1
    assert checked > 100
    assert set(flight.seen[1]) == {
        "vehicle_angular_velocity",
        "actuator_controls_0",
        "vehicle_attitude",
        "actuator_outputs[1]",
    }
    assert flight.seen[1]["actuator_outputs[1]"] == len(out1["timestamp"])


def test_instances_of_a_topic_are_told_apart() -> None:
    log = open_onboard_log(APPENDED)
    text = """
[signals]
instant = "actuator_outputs"
outputs = ["out0"]
actuator = ["out1"]
[signals.measured]
out0 = { field = "actuator_outputs.output[0]" }
out1 = { field = "actuator_outputs[1].output[0]", hold = 0.1 }
"""
    with pytest.raises(UserError, match="actuator 'out1': 'hold' makes it a latest value"):
        _map(text, log)
    smap = _map(text.replace(", hold = 0.1 }", " }"), log)
    assert smap.measured["out1"].message == "actuator_outputs[1]"
    recs = list(log.records({"actuator_outputs": {"output"}, "actuator_outputs[1]": {"output"}}))
    from pyulog import ULog

    ulog = ULog(str(APPENDED))
    for multi_id, name in ((0, "actuator_outputs"), (1, "actuator_outputs[1]")):
        data = ulog.get_dataset("actuator_outputs", multi_id).data
        mine = [(t, v[log.layouts(name).position("output", 0)]) for n, v, t in recs if n == name]
        assert [t for t, _ in mine] == data["timestamp"].tolist()
        assert [v for _, v in mine] == pytest.approx(data["output[0]"].astype(float).tolist())
    stamps = [t for _n, _v, t in recs]
    assert stamps == sorted(stamps)  # one clock: the topics' records merged in time order


@pytest.mark.parametrize(
    "field, message",
    [
        ("airspeed_validated.true_airspeed_m_s", "unknown ULog topic 'airspeed_validated' (this log's topics: "),
        (
            "vehicle_attitude.pitch",
            "vehicle_attitude has no field 'pitch' (fields: timestamp, rollspeed, pitchspeed, yawspeed, q)",
        ),
        ("vehicle_attitude.q[4]", "vehicle_attitude.q[4] is out of range (4 values)"),
        ("actuator_outputs[2].output[0]", "unknown ULog topic 'actuator_outputs[2]'"),
    ],
)
def test_a_map_naming_what_the_log_lacks_is_a_one_line_error(field: str, message: str) -> None:
    log = open_onboard_log(APPENDED)
    text = RATE_MAP.replace("vehicle_angular_velocity", "vehicle_attitude").replace(
        '"vehicle_attitude.xyz[1]"', json.dumps(field)
    )
    with pytest.raises(UserError) as err:
        _map(text, log)
    assert message in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_analyse_takes_a_ulog_and_says_what_it_holds(tmp_path: Path, capsys) -> None:
    from tests.gains_files import hand_made_gains_file

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    (tmp_path / "px4.toml").write_text(RATE_MAP)
    copy = tmp_path / "flight.bin"  # told by content, not by name
    copy.write_bytes(SMALL.read_bytes())
    argv = ["analyse", str(copy), "--plant", "paper-continuous", "--gains", str(gains), "--signals"]
    code = main([*argv, str(tmp_path / "px4.toml"), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    report = json.loads(captured.out)
    assert report["log"]["inventory"]["kind"] == "ulog" and report["log"]["processed"] > 0
    code = main([*argv, str(tmp_path / "px4.toml")])
    out = capsys.readouterr().out
    assert code == 0 and "log holds: 14604 ULog data messages over 1174.1 s of timestamp, 55 topics in 70" in out
    assert re.search(r"log holds: topics actuator_controls_0 1\.54 Hz, ", out), out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["analyse", "{ulg}", "--plant", "paper-continuous", "--gains", "{gains}"], "a ULog log names PX4's topics"),
        (["identify", "{ulg}", "--out", "{work}/p.toml"], "a ULog log names PX4's topics"),
        (["identify", "{bad}", "--out", "{work}/p.toml"], "cannot read the ULog log"),
    ],
)
def test_ulog_mistakes_are_one_line_exit_2(tmp_path: Path, capsys, argv, message) -> None:
    from tests.gains_files import hand_made_gains_file

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    bad = tmp_path / "torn.ulg"
    bad.write_bytes(SMALL.read_bytes()[:12])
    args = [a.format(ulg=SMALL, gains=gains, work=tmp_path, bad=bad) for a in argv]
    code = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if "error" in line]
    assert code == 2 and len(errors) == 1 and message in errors[0], err


DERIVED_MAP = """
[signals]
instant = "vehicle_local_position"
outputs = ["alpha"]
actuator = ["pitch_control"]
[signals.measured]
pitch_control = { field = "actuator_controls_0.control[1]" }
[signals.measured.alpha]
derive = "angle_of_attack"
velocity_ned = ["vehicle_local_position.vx", "vehicle_local_position.vy", "vehicle_local_position.vz"]
attitude_quaternion = [
    { field = "vehicle_attitude.q[0]", hold = 0.1 }, { field = "vehicle_attitude.q[1]", hold = 0.1 },
    { field = "vehicle_attitude.q[2]", hold = 0.1 }, { field = "vehicle_attitude.q[3]", hold = 0.1 },
]
"""


def test_a_derived_angle_of_attack_from_a_real_log_is_scipy_s_rotation_of_its_arrays() -> None:
    """A multicopter's α is of no use, but it is computed all the same: from the 10 Hz NED velocity and the
    30 Hz attitude held (the newest record when the sample completes: the one at or before the instant, or the
    next when the actuator's record comes after the instant's), equal to the velocity rotated into body axes by
    scipy's Rotation from pyulog's own arrays."""
    from pyulog import ULog
    from scipy.spatial.transform import Rotation

    log = open_onboard_log(APPENDED)
    smap = _map(DERIVED_MAP, log)
    h = log_spacing(str(APPENDED), smap.instant, None, dataflash=log)
    assert h is not None
    flight = read_flight(str(APPENDED), smap, h, dataflash=log)
    rows = flight.samples[1]
    ulog = ULog(str(APPENDED))
    pos = ulog.get_dataset("vehicle_local_position").data
    att = ulog.get_dataset("vehicle_attitude").data
    assert len(rows) == len(pos["timestamp"]) == 95
    quats = np.column_stack([att[f"q[{i}]"] for i in (1, 2, 3, 0)])  # scipy: x, y, z, w
    for (_k, values), i in zip(rows, range(len(rows)), strict=True):
        t = int(pos["timestamp"][i])
        v_ned = [float(pos[c][i]) for c in ("vx", "vy", "vz")]
        j = int(np.searchsorted(att["timestamp"], t, side="right")) - 1
        candidates = []
        for jj in (j, j + 1):
            if 0 <= jj < len(quats):
                u, _v, w = Rotation.from_quat(quats[jj]).inv().apply(v_ned)
                candidates.append(math.degrees(math.atan2(w, u)))
        assert min(abs(values["alpha"] - c) for c in candidates) < 1e-4, (values["alpha"], candidates)


def test_a_damaged_ulog_gives_its_good_records_one_warning_and_clean_json(tmp_path: Path, capsys, caplog) -> None:
    """2 kB overwritten in the middle (a torn write): pyulog resynchronises and says so on stdout, which would
    corrupt --json; the monitor says it in one WARNING and reads the records around the damage."""
    from tests.gains_files import hand_made_gains_file

    data = bytearray(APPENDED.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 2000] = bytes(range(256)) * 7 + bytes(208)
    torn = tmp_path / "torn.ulg"
    torn.write_bytes(bytes(data))
    (tmp_path / "map.toml").write_text(DERIVED_MAP)
    gains = hand_made_gains_file(tmp_path / "gains.toml")
    argv = ["analyse", str(torn), "--plant", "paper-continuous", "--gains", str(gains), "--signals"]
    with caplog.at_level("WARNING"):
        code = main([*argv, str(tmp_path / "map.toml"), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    report = json.loads(captured.out)  # nothing of pyulog's on stdout
    whole = open_onboard_log(APPENDED).inventory.records
    assert 0.5 * whole < report["log"]["inventory"]["records"] < whole
    warnings = [r for r in caplog.records if r.levelname == "WARNING" and "pyulog" in r.getMessage()]
    assert len(warnings) == 1, [r.getMessage() for r in caplog.records]
