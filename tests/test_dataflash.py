"""ArduPilot DataFlash logs (``monitor/link/dataflash.py``) through ``analyse`` and ``identify``.

The logs are written here to the published binary format (ArduPilot's ``AP_Logger``: every record is the header
0xA3 0x95, a message type and its packed fields; type 128 is FMT, whose own format is ``BBnNZ``: type, length,
name[4], format[16], columns[64]; FMT records first, then data) and read back by pymavlink's DFReader to prove
them valid before the monitor reads them. Messages are ArduPlane's: ATT (centidegrees, 'c'), RATE (deg/s),
AOA (deg), RCOU (servo PWM, us), ARSP (m/s), with every record stamped a random 0-8 ms after its sample's
instant (TimeUS), as a real autopilot writes them. The text form (``.log``, what mavlogdump writes) too.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.errors import UserError
from tests.dataflash_formats import (
    ARDUPLANE_MAP,
    FORMATS,
    T0_US,
    fmt_of_fmt,
    fmt_record,
    pack_record,
    short_period_flight,
    write_dataflash,
)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    work = tmp_path_factory.mktemp("df")
    A, B, samples = short_period_flight()
    path = work / "00000042.BIN"
    write_dataflash(path, samples, 0.02)
    (work / "arduplane.toml").write_text(ARDUPLANE_MAP)
    return {"work": work, "bin": path, "A": A, "B": B, "samples": samples, "map": work / "arduplane.toml"}


def test_the_written_log_is_a_dataflash_log_pymavlink_reads(flight) -> None:
    from pymavlink import DFReader

    reader = DFReader.DFReader_binary(str(flight["bin"]))
    counts = {}
    first = {}
    while (m := reader.recv_msg()) is not None:
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
        first.setdefault(m.get_type(), m)
    n = len(flight["samples"])
    assert {k: counts[k] for k in ("ATT", "RATE", "AOA", "RCOU", "ARSP")} == dict.fromkeys(
        ("ATT", "RATE", "AOA", "RCOU", "ARSP"), n
    )
    assert first["ATT"].Pitch == pytest.approx(2.0) and first["AOA"].AOA == pytest.approx(2.0)
    assert first["RCOU"].C2 == 1450 and first["PARM"].Name == "SYSID_THISMAV"


def test_identify_a_dataflash_log_with_arduplanes_signal_map(flight, capsys) -> None:
    out = flight["work"] / "sp.toml"
    code = main(
        [
            "identify",
            str(flight["bin"]),
            "--signals",
            str(flight["map"]),
            "--model",
            "short-period",
            "--out",
            str(out),
            "--json",
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    report = json.loads(captured.out)
    n = len(flight["samples"])
    assert report["samples"]["log"] == n and report["h"] == pytest.approx(0.02, rel=1e-3)
    assert min(report["fit_percent"].values()) > 95, report["fit_percent"]
    from monitor.model.plant import load_plant

    plant = load_plant(out)
    assert np.allclose(plant.continuous.A_c, flight["A"], rtol=0.01, atol=0), plant.continuous.A_c
    assert np.allclose(plant.continuous.B_c, flight["B"], rtol=0.01, atol=0), plant.continuous.B_c
    inv = report["log"]["inventory"]
    assert inv["kind"] == "dataflash" and inv["records"] == 5 * n + 1 + 1 + len(FORMATS)  # + PARM and the FMTs
    hz = {m["name"]: m["hz"] for m in inv["messages"]}
    assert hz["RCOU"] == pytest.approx(50.0, rel=0.02) and hz["ATT"] == pytest.approx(50.0, rel=0.02)


def test_analyse_gives_the_same_estimates_from_a_dataflash_log_and_a_tlog(tmp_path: Path, capsys) -> None:
    """One autopilot-flown flight of the paper's plant (h = 1 s), logged twice: as DataFlash (AOA, RCOU) and as a
    tlog (AOA_SSA, SERVO_OUTPUT_RAW), the same float32 and PWM values at the same TimeUS: same samples, same f_hat."""
    from monitor.model.plant import load_plant
    from monitor.wire.mavlink import mavlink, new_codec
    from tests.gains_files import hand_made_gains_file

    plant = load_plant("paper-continuous")
    x, u_prev, rows = np.zeros(2), 0.0, []
    for k in range(60):
        y = float(np.float32((plant.C @ x)[0]))
        pwm = round(1500 + (-0.5 * y) / 0.06)
        u = (pwm - 1500) * 0.06
        rows.append({"alpha": y, "q": 0.0, "theta": 0.0, "pwm": pwm})
        x = plant.A @ x + (plant.B0 * u + plant.B1 * u_prev + plant.Df * (2.0 if k >= 20 else 0.0)).ravel()
        u_prev = u
    dataflash = tmp_path / "flight.bin"
    write_dataflash(dataflash, rows, 1.0, seed=3)
    text = tmp_path / "flight.log"
    write_dataflash(text, rows, 1.0, seed=3, text=True)
    from pymavlink import DFReader

    records = []
    reader = DFReader.DFReader_binary(str(dataflash))
    while (m := reader.recv_match(type=["AOA", "RCOU"])) is not None:
        records.append(m)
    codec = new_codec(1, 1)
    tlog = tmp_path / "flight.tlog"
    with open(tlog, "wb") as fh:
        for m in records:
            if m.get_type() == "AOA":
                msg = mavlink.MAVLink_aoa_ssa_message(m.TimeUS, m.AOA, 0.0)
            else:
                msg = mavlink.MAVLink_servo_output_raw_message(m.TimeUS, 0, m.C1, m.C2, m.C3, m.C4, 0, 0, 0, 0)
            codec.send(msg)
            fh.write(struct.pack(">Q", 1_700_000_000_000_000 + m.TimeUS) + codec.file.take())
    (tmp_path / "df.toml").write_text(
        '[signals]\ninstant = "RCOU"\noutputs = ["alpha"]\nactuator = ["elevator"]\n'
        '[signals.measured]\nalpha = { field = "AOA.AOA", unit = "deg" }\n'
        'elevator = { field = "RCOU.C2", scale = 0.06, offset = -90.0, unit = "deg" }\n'
    )
    (tmp_path / "tlog.toml").write_text(
        '[signals]\ninstant = "SERVO_OUTPUT_RAW"\noutputs = ["alpha"]\nactuator = ["elevator"]\n[signals.measured]\n'
        'alpha = { field = "AOA_SSA.AOA", unit = "deg" }\n'
        'elevator = { field = "SERVO_OUTPUT_RAW.servo2_raw", scale = 0.06, offset = -90.0, unit = "deg" }\n'
    )
    gains = hand_made_gains_file(tmp_path / "gains.toml")
    from monitor.link.dataflash import open_dataflash
    from monitor.service.alarm import AlarmConfig
    from monitor.service.fleet_file import Fleet, load_model
    from monitor.service.offline import analyse_dataflash, analyse_log

    f_hat = {}
    for log in (dataflash, text):
        dlog = open_dataflash(log)
        fleet = Fleet(load_model("paper-continuous", gains, signals_file=tmp_path / "df.toml", layouts=dlog.layouts))
        f_hat[log.suffix] = [r.f_hat[0] for r in analyse_dataflash(dlog, fleet, AlarmConfig()).records]
    fleet = Fleet(load_model("paper-continuous", gains, signals_file=tmp_path / "tlog.toml"))
    f_hat[".tlog"] = [r.f_hat[0] for r in analyse_log(tlog, fleet, AlarmConfig()).records]
    assert f_hat[".bin"] == f_hat[".tlog"] and len(f_hat[".bin"]) == 60
    assert f_hat[".log"] == pytest.approx(f_hat[".bin"], rel=1e-6, abs=1e-6)  # text: values as printed, 9 digits
    code = main(
        [
            "analyse",
            str(dataflash),
            "--plant",
            "paper-continuous",
            "--gains",
            str(gains),
            "--signals",
            str(tmp_path / "df.toml"),
            "--json",
        ]
    )
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["samples"] == 60
    inv = report["log"]["inventory"]
    assert inv["kind"] == "dataflash" and {m["name"] for m in inv["messages"]} >= {"ATT", "RATE", "AOA", "RCOU"}
    code = main(
        [
            "analyse",
            str(dataflash),
            "--plant",
            "paper-continuous",
            "--gains",
            str(gains),
            "--signals",
            str(tmp_path / "df.toml"),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0 and "log holds: 309 DataFlash records over 59.5 s of TimeUS, 7 messages" in out, out


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["analyse", "{bin}", "--plant", "paper-continuous", "--gains", "{gains}"],
            "a DataFlash log names its own messages: give a signal map of them with --signals FILE",
        ),
        (
            ["analyse", "{bin}", "--plant", "paper-continuous", "--gains", "{gains}", "--signals", "{mav}"],
            "unknown DataFlash message 'AOA_SSA' (this log's messages: AOA, ARSP, ATT, CTUN, FMT, PARM, RATE, RCOU)",
        ),
        (
            ["analyse", "{bin}", "--plant", "paper-continuous", "--gains", "{gains}", "--signals", "{ctun}"],
            "missing signals: alpha (CTUN.Pitch): the log has no CTUN; "
            "what the log has instead: angle of attack: AOA 49",
        ),
        (
            ["identify", "{bin}", "--out", "{work}/p.toml"],
            "a DataFlash log names its own messages: give a signal map of them with --signals FILE",
        ),
        (["identify", "{empty}", "--out", "{work}/p.toml", "--signals", "{map}"], "holds no data records"),
        (["identify", "{bin}", "--out", "{work}/p.toml", "--signals", "{map}", "--sysid", "0"], "--sysid must be"),
    ],
)
def test_dataflash_mistakes_are_one_line_exit_2(flight, tmp_path: Path, capsys, argv, message) -> None:
    from tests.gains_files import hand_made_gains_file

    gains = hand_made_gains_file(tmp_path / "gains.toml")
    (tmp_path / "mav.toml").write_text(
        '[signals]\ninstant = "AOA_SSA"\noutputs = ["alpha"]\nactuator = ["e"]\n'
        '[signals.measured]\nalpha = { field = "AOA_SSA.AOA" }\n'
        'e = { field = "RCOU.C2" }\n'
    )
    (tmp_path / "ctun.toml").write_text(
        '[signals]\ninstant = "RCOU"\noutputs = ["alpha"]\nactuator = ["e"]\n'
        '[signals.measured]\nalpha = { field = "CTUN.Pitch" }\ne = { field = "RCOU.C2" }\n'
    )
    empty = tmp_path / "empty.bin"
    empty.write_bytes(fmt_of_fmt() + fmt_record("AOA"))
    args = [
        a.format(
            bin=flight["bin"],
            gains=gains,
            mav=tmp_path / "mav.toml",
            ctun=tmp_path / "ctun.toml",
            work=tmp_path,
            empty=empty,
            map=flight["map"],
        )
        for a in argv
    ]
    code = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if "error" in line]
    assert code == 2 and len(errors) == 1 and message in errors[0], err
    assert not any("Traceback" in line for line in err)


def test_a_damaged_dataflash_log_gives_its_good_records_and_one_warning(flight, tmp_path: Path, capsys, caplog) -> None:
    """Garbage in the middle of the log (a torn write): pymavlink skips it and says so on stderr; the monitor keeps
    its stdout clean (--json) and says it in one WARNING; the records around the damage still make samples."""
    data = flight["bin"].read_bytes()
    cut = len(data) // 2
    damaged = tmp_path / "damaged.bin"
    damaged.write_bytes(data[:cut] + bytes(range(1, 200)) * 4 + data[cut + 800 :])  # ~20 records overwritten
    out = tmp_path / "p.toml"
    code = main(
        [
            "identify",
            str(damaged),
            "--signals",
            str(flight["map"]),
            "--model",
            "short-period",
            "--out",
            str(out),
            "--json",
        ]
    )
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert code == 0 and len(flight["samples"]) - 6 <= report["samples"]["log"] < len(flight["samples"])
    warnings = [r.message for r in caplog.records if "DataFlash reader" in r.message]
    assert len(warnings) == 1 and "Skipped" in warnings[0] and "bad header" not in captured.err, warnings


def test_a_format_record_naming_fewer_columns_than_fields_is_a_one_line_error(tmp_path: Path) -> None:
    """pymavlink reads an FMT whose column names are fewer than its fields; its values could not be named."""
    from monitor.link.dataflash import open_dataflash

    corrupt = dict(FORMATS, AOA=(131, "Qff", "TimeUS,AOA"))
    path = tmp_path / "corrupt.bin"
    with open(path, "wb") as fh:
        fh.write(fmt_of_fmt())
        for name in ("AOA", "RCOU"):
            fh.write(fmt_record(name, corrupt))
        fh.write(
            pack_record("AOA", [T0_US, 1.0, 0.0]) + pack_record("RCOU", [T0_US, 1500, 1500, 1200, 1500] + [0] * 10)
        )
    dlog = open_dataflash(path)
    with pytest.raises(UserError, match=r"FMT record of AOA declares 3 fields but names 2 columns \(a corrupt log\)"):
        dlog.layouts("AOA")
    assert dlog.layouts("RCOU") is not None  # the sound messages of the log stay readable
