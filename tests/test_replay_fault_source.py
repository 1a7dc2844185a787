"""``replay --fault``: validated always; with truth and a SPEC it says which it scores; no fault known, no verdict."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from monitor.scoring import score_recording
from monitor.service.recorder import RrdRecorder
from monitor.service.recording_reader import load_recording
from monitor.service.records import SampleRecord, TruthRecord


def _recording(path: Path, truth: bool) -> Path:
    wall = time.time()
    with RrdRecorder(path) as rec:
        for k in range(40):
            f = 2.0 if k >= 20 else 0.0
            rec.submit(
                SampleRecord(
                    sysid=1,
                    k=k,
                    t=float(k),
                    wall=wall + k,
                    y=[0.1],
                    alpha=0.1,
                    q=0.0,
                    elevator=None,
                    x_hat=[0.0, 0.0],
                    f_hat=[f],
                    u=[0.0],
                    residual=[0.0],
                    tau_obs=None,
                    processing_s=1e-5,
                    alarm=5 <= k < 7 or k >= 21,
                )
            )
            if truth:
                rec.submit_truth(TruthRecord(sysid=1, k=k, t=float(k), x=[0.0, 0.0], f=[f], d=[0.0], tau=0.1))
    return path


def test_false_alarms_do_not_depend_on_how_the_onset_was_learned(tmp_path: Path) -> None:
    bare = load_recording(_recording(tmp_path / "bare.rrd", truth=False))
    assert score_recording(bare)["false_alarms"] is None  # no truth, no SPEC: a raise cannot be called false
    assert score_recording(bare, fault_spec="bias:2@20")["false_alarms"] == 1
    with_truth = load_recording(_recording(tmp_path / "truth.rrd", truth=True))
    assert score_recording(with_truth)["false_alarms"] == 1
    both = score_recording(with_truth, fault_spec="bias:2@30")
    assert both["fault_source"] == "spec" and both["onset_k"] == 30 and "also holds" in both["fault_note"]


def test_a_bad_spec_is_one_line_even_when_truth_was_recorded(tmp_path: Path) -> None:
    path = _recording(tmp_path / "truth.rrd", truth=True)
    out = subprocess.run(
        [sys.executable, "-m", "monitor", "replay", str(path), "--fault", "bias:x@1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr
    ok = subprocess.run(
        [sys.executable, "-m", "monitor", "replay", str(path), "--fault", "bias:2@20"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ok.returncode == 0 and "scored against --fault bias:2@20" in ok.stdout
