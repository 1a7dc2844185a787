"""RrdRecorder writes every submitted sample to a complete .rrd, never raises, and survives a SIGTERM."""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

from monitor.errors import UserError  # noqa: E402
from monitor.service.recorder import RrdRecorder  # noqa: E402
from monitor.service.recording_reader import load_recording  # noqa: E402
from monitor.service.records import SampleRecord, TruthRecord  # noqa: E402
from tests.recordings import make_run, write_run  # noqa: E402


def assert_same(got: SampleRecord | TruthRecord, want: SampleRecord | TruthRecord) -> None:
    for name, value in dataclasses.asdict(want).items():
        if value is None:
            assert getattr(got, name) is None, (name, got, want)
        else:
            assert getattr(got, name) == pytest.approx(value, rel=1e-12, abs=1e-9), (name, got, want)


def test_every_sample_and_truth_row_comes_back(tmp_path: Path) -> None:
    path = tmp_path / "run.rrd"
    runs = write_run(path, skip=frozenset({50, 51}))
    recording = load_recording(path)
    assert recording.has_footer
    assert set(recording.vehicles) == {1, 2}
    for sysid, (samples, truths) in runs.items():
        got = recording.vehicles[sysid]
        assert len(samples) == 198 and len(got.samples) == len(samples)  # the strict zip below checks it too
        assert [r.k for r in got.samples] == [r.k for r in samples]
        for g, w in zip(got.samples, samples, strict=True):
            assert_same(g, w)
        assert len(truths) == 200 and len(got.truth) == len(truths)
        for g, w in zip(got.truth, truths, strict=True):
            assert_same(g, w)
    props = recording.properties
    assert props["plant"] == "paper" and props["plant_hash"] == "abc123" and props["layout"] == "1"
    assert {"fault_monitor_version", "rerun_sdk_version", "pymavlink_version", "zenoh_version"} <= set(props)


def test_file_holds_a_blueprint_and_passes_rerun_verify(tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    path = tmp_path / "run.rrd"
    write_run(path, n=30)
    assert RrdReader(path).blueprints(), "no default blueprint in the file"
    cli = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    if cli is None:
        pytest.skip("rerun CLI not on PATH")
    done = subprocess.run(
        [cli, "rrd", "verify", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )
    assert done.returncode == 0, done.stderr


def test_failures_are_logged_once_and_never_raise(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    rec = RrdRecorder(tmp_path / "broken.rrd")
    samples, _ = make_run(1, n=100)

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("disk on fire")

    rec._rec.send_record_batch = boom  # type: ignore[method-assign]
    with caplog.at_level(logging.ERROR, logger="monitor.service.recorder"):
        for s in samples:
            rec.submit(s)
        rec.close()
        rec.close()
        rec.submit(samples[0])  # after close: counted, logged, not raised
    lines = [r for r in caplog.records if "disk on fire" in r.getMessage()]
    assert len(lines) == 1
    assert rec.stats["failed"] == 100 and rec.stats["written"] == 0


def test_unwritable_path_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError):
        RrdRecorder(tmp_path / "no" / "such" / "dir" / "x.rrd")
    with pytest.raises(UserError):
        RrdRecorder(tmp_path)


CHILD = textwrap.dedent("""
    import os, signal, sys, time
    from monitor.service.recorder import RrdRecorder
    from tests.recordings import make_run

    rec = RrdRecorder(sys.argv[1])
    samples, truth = make_run(7, n=100_000)
    sent = 0

    def stop(signum, frame):  # what `fault-monitor run` does on SIGTERM: flush, footer, exit 0
        rec.close()
        # os.write, not print: the signal may land while the main thread is inside print("ready"), and a second
        # print re-entering sys.stdout's buffer raises (it did, on a loaded machine)
        os.write(1, f"{sent}\\n".encode())
        os._exit(0)  # no interpreter teardown: the file must already be complete

    signal.signal(signal.SIGTERM, stop)
    for s, t in zip(samples, truth):
        rec.submit(s)
        rec.submit_truth(t)
        sent += 1
        if sent == 300:
            print("ready", flush=True)
        time.sleep(0.0002)
""")


def test_sigterm_mid_run_leaves_a_complete_recording(tmp_path: Path) -> None:
    path = tmp_path / "killed.rrd"
    root = Path(__file__).resolve().parents[1]
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=root,
        env={**os.environ, "RERUN_ANALYTICS": "0", "PYTHONPATH": str(root)},
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "ready"
        child.send_signal(signal.SIGTERM)
        sent = int(child.stdout.readline())
        assert child.wait(timeout=20) == 0
    finally:
        child.kill()
    recording = load_recording(path)
    assert recording.has_footer
    got = recording.vehicles[7]
    assert len(got.samples) == sent >= 300 and len(got.truth) == sent
    assert [r.k for r in got.samples] == list(range(sent))


def test_numpy_fields_from_the_estimator_are_accepted(tmp_path: Path) -> None:
    """The loop may hand over ``StepResult`` arrays and numpy scalars as they are."""
    import numpy as np

    path = tmp_path / "np.rrd"
    samples, _ = make_run(4, n=10)
    with RrdRecorder(path) as rec:
        for s in samples:
            rec.submit(
                dataclasses.replace(
                    s,
                    x_hat=np.array(s.x_hat),
                    f_hat=np.array(s.f_hat),
                    u=np.array(s.u),
                    residual=np.array(s.residual),
                    alpha=np.float64(s.alpha),
                    alarm=np.bool_(s.alarm),
                )
            )
    recording = load_recording(path)
    assert set(recording.vehicles) == {4}
    got_samples = recording.vehicles[4].samples
    assert len(samples) == 10 and len(got_samples) == len(samples)  # the strict zip below checks it too
    for got, want in zip(got_samples, samples, strict=True):
        assert_same(got, want)


def test_recording_properties_describe_plant_and_gains(tmp_path: Path) -> None:
    import json

    import numpy as np

    from monitor.model.closed_loop import Gains
    from monitor.model.plant import load_plant
    from monitor.service.rrd_stream import recording_properties

    plant = load_plant("paper")
    gains = Gains(
        L=np.full((plant.n, plant.l), 0.5),
        M=np.full((plant.q, plant.l), 0.1),
        K1=np.zeros((plant.m, plant.l)),
        K2=np.zeros((plant.m, plant.m)),
        K3=np.zeros((plant.m, plant.q)),
    )
    props = recording_properties(plant, gains, "certified", "gains.toml")
    path = tmp_path / "props.rrd"
    RrdRecorder(path, properties=props).close()
    got = load_recording(path).properties
    assert got["plant_name"] == plant.name and got["plant_hash"] == plant.digest and got["gains_method"] == "certified"
    assert np.allclose(json.loads(got["gains_L"]), gains.L)
