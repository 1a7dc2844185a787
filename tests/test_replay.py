"""``fault-monitor replay`` on real recordings: the scores, the JSON shape, and one-line errors."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

from monitor.cli import main  # noqa: E402
from tests.recordings import LAG, ONSET, SIZE, write_run  # noqa: E402

CONTRACT_KEYS = {"samples", "settling_steps", "rms_ef", "peak_alpha"}


def replay(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(["replay", *argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rrd") / "fleet.rrd"
    write_run(path, sysids=(1, 2), n=200, skip=frozenset({50, 51}))
    return path


def test_single_vehicle_json_has_contract_keys_and_right_scores(
    capsys: pytest.CaptureFixture[str], fleet: Path
) -> None:
    code, out, _ = replay(capsys, str(fleet), "--json", "--sysid", "2")
    assert code == 0
    report = json.loads(out)
    assert CONTRACT_KEYS <= set(report)
    assert report["samples"] == 198 and report["missing"] == 2
    assert report["settling_steps"] == LAG and report["onset_k"] == ONSET and report["fault_size"] == SIZE
    assert report["fault_source"] == "truth"
    # e_f = 2 on k = 20..24, 0 elsewhere; 198 samples
    assert report["rms_ef"] == pytest.approx((LAG * SIZE**2 / 198) ** 0.5)
    assert report["detection_steps"] == 3 and report["first_alarm_k"] == ONSET + 3 and report["false_alarms"] == 0
    assert report["detection_s"] == pytest.approx(1.5) and report["h"] == pytest.approx(0.5)
    assert report["peak_alpha"] == pytest.approx(2.0, abs=0.01)  # |2 sin(k/7)| peaks near 2
    assert report["processing_ms"]["max"] == pytest.approx(0.09)
    assert report["tau_obs_s"]["n"] == 197 and report["tau_true_s"]["n"] == 200
    assert list(report["vehicles"]) == ["2"] and report["properties"]["plant"] == "paper"


def test_fleet_json_summarises_and_keeps_each_vehicle(capsys: pytest.CaptureFixture[str], fleet: Path) -> None:
    code, out, _ = replay(capsys, str(fleet), "--json")
    report = json.loads(out)
    assert code == 0 and CONTRACT_KEYS <= set(report)
    assert report["sysids"] == [1, 2] and report["samples"] == 396
    assert report["settling_steps"] == LAG and report["peak_alpha"] == pytest.approx(2.0, abs=0.01)
    assert {v["samples"] for v in report["vehicles"].values()} == {198}


def test_fault_spec_scores_a_recording_without_truth(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "notruth.rrd"
    write_run(path, sysids=(3,), n=80, truth=False)
    report = json.loads(replay(capsys, str(path), "--json")[1])
    assert report["settling_steps"] is None and report["rms_ef"] is None and report["fault_source"] is None
    report = json.loads(replay(capsys, str(path), "--json", "--fault", f"bias:{SIZE}@{ONSET}")[1])
    assert report["fault_source"] == "spec" and report["settling_steps"] == LAG and report["detection_steps"] == 3
    report = json.loads(replay(capsys, str(path), "--json", "--fault", f"bias:{SIZE}@{ONSET}-30")[1])
    assert report["settling_steps"] == LAG  # scored on the faulty episode [20, 30) only


def test_text_report_reads_like_the_help(capsys: pytest.CaptureFixture[str], fleet: Path) -> None:
    code, out, _ = replay(capsys, str(fleet))
    assert code == 0
    assert "vehicle 1: 198 samples" in out and "settling       5 steps" in out and "fleet: 396 samples" in out


@pytest.mark.parametrize("content", [b"", b"not a recording at all\n", b"RRF2" + bytes(range(256)) * 8])
def test_corrupt_file_is_one_line_exit_2(capsys: pytest.CaptureFixture[str], tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bad.rrd"
    path.write_bytes(content)
    code, out, err = replay(capsys, str(path))
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and "error" in err


def test_truncated_file_is_one_line_exit_2(capsys: pytest.CaptureFixture[str], fleet: Path, tmp_path: Path) -> None:
    path = tmp_path / "cut.rrd"
    path.write_bytes(fleet.read_bytes()[: fleet.stat().st_size * 2 // 3])
    code, _, err = replay(capsys, str(path))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "rerun rrd optimize" in err


def test_missing_foreign_and_unknown_vehicle_are_user_errors(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, fleet: Path
) -> None:
    import rerun as rr

    foreign = tmp_path / "foreign.rrd"
    rec = rr.RecordingStream("someone-else")
    rec.save(str(foreign))
    rec.log("/points", rr.Points2D([[0, 0]]))
    rec.disconnect()
    for argv in ([str(tmp_path / "missing.rrd")], [str(foreign)], [str(fleet), "--sysid", "9"]):
        code, _, err = replay(capsys, *argv)
        assert code == 2 and len(err.strip().splitlines()) == 1, (argv, err)


def test_empty_recording_reports_zero_samples(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from monitor.service.recorder import RrdRecorder

    path = tmp_path / "empty.rrd"
    RrdRecorder(path).close()  # a monitor that never heard from a vehicle
    code, out, _ = replay(capsys, str(path), "--json")
    report = json.loads(out)
    assert code == 0 and report["samples"] == 0 and report["sysids"] == [] and report["settling_steps"] is None
    assert replay(capsys, str(path))[1].splitlines()[-1] == "no samples recorded"
