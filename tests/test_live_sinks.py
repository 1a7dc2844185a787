"""A live viewer's sink: addresses checked up front, a bounded queue that keeps the newest samples, one WARNING.

Real parts only: a port where nothing listens, and a headless ``rerun --save`` viewer started late.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import pytest

from monitor.errors import UserError
from monitor.service.live_sinks import LiveSink, find_viewer, parse_viewer_url
from tests.daemons import free_tcp_port, wait_for
from tests.recordings import make_run


def _sink(port: int, **kwargs: object) -> LiveSink:
    return LiveSink(
        f"rerun+http://127.0.0.1:{port}/proxy",
        "fault-monitor",
        "test-recording",
        {"layout": "1"},
        "live test",
        **kwargs,
    )


def test_viewer_addresses_are_checked() -> None:
    assert parse_viewer_url("rerun+http://127.0.0.1:9876/proxy") == ("127.0.0.1", 9876)
    assert parse_viewer_url("rerun+https://[::1]:443/proxy/") == ("::1", 443)
    for bad in (
        "http://127.0.0.1:9876/proxy",
        "rerun://127.0.0.1:9876/proxy",
        "rerun+http://127.0.0.1/proxy",
        "rerun+http://127.0.0.1:9876/",
        "rerun+http://127.0.0.1:99999/proxy",
        "rerun+http://:9876/proxy",
        "127.0.0.1:9876",
    ):
        with pytest.raises(UserError, match="--rerun-url"):
            parse_viewer_url(bad)


def test_the_viewer_executable_is_found_or_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="--rerun-spawn"):
        find_viewer(search_path=str(tmp_path))
    assert Path(find_viewer(search_path=str(Path(sys.executable).parent))).name == "rerun"


def test_nobody_listening_keeps_the_newest_samples_and_warns_once(caplog: pytest.LogCaptureFixture) -> None:
    samples, _ = make_run(1, n=250)
    with caplog.at_level(logging.INFO, logger="monitor.service.live_sinks"):
        sink = _sink(free_tcp_port(), maxlen=100, probe_s=0.05)
        took = []
        for s in samples:
            t0 = time.perf_counter()
            sink.put(s)
            took.append(time.perf_counter() - t0)
        time.sleep(0.3)  # a few probes: still one WARNING
        assert [r.k for r in sink._pending] == list(range(150, 250))
        assert sink.stats["dropped"] == 150 and sink.stats["written"] == 0 and not sink.connected
        t0 = time.monotonic()
        sink.close()
        sink.join(2.0)
        assert time.monotonic() - t0 < 1.0, "closing a sink that never connected must not wait on Rerun"
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "nothing answers" in warnings[0], warnings
    # put never waits on the network: nine in ten under 5 ms (the slowest one timed the test process's preemption
    # on a busy machine, not put: 250 puts take a few ms in all, so one preemption lands in one of them)
    slow = sorted(took)[len(took) * 9 // 10]
    assert slow < 0.005, f"one put in ten took {slow * 1e6:.0f} us or more"


def test_a_viewer_started_late_gets_the_kept_samples(tmp_path: Path) -> None:
    from tests.rerun_viewer import headless_viewer, load_when_complete

    port, out = free_tcp_port(), tmp_path / "late.rrd"
    samples, _ = make_run(1, n=80)
    sink = _sink(port, maxlen=50, probe_s=0.1)
    try:
        for s in samples:
            sink.put(s)
        with headless_viewer(tmp_path, port, out):
            wait_for(lambda: sink.connected, 30, what="the sink connecting")
            wait_for(lambda: sink.stats["written"] == 50, 30, what="the kept samples sent")
            sink.close()
            sink.join(5.0)
            got = load_when_complete(out, 50)
    finally:
        sink.close()
    assert [s.k for s in got.vehicles[1].samples] == list(range(30, 80))
    assert sink.stats["dropped"] == 30 and sink.connections == 1


def test_a_recorder_with_only_a_live_viewer_never_waits_for_it() -> None:
    """No ``--rrd``: the recorder still takes every sample at once and closes at once; no file error."""
    from monitor.service.recorder import RrdRecorder

    samples, truth = make_run(2, n=300)
    rec = RrdRecorder(None, live=[f"rerun+http://127.0.0.1:{free_tcp_port()}/proxy"])
    t0 = time.monotonic()
    for s, t in zip(samples, truth, strict=True):
        rec.submit(s)
        rec.submit_truth(t)
    rec.close()
    assert time.monotonic() - t0 < 1.0
    [sink] = rec.live
    assert rec.error is None and rec.path is None and sink.stats["submitted"] == 600 and sink.stats["dropped"] == 0


def test_a_spawned_viewer_is_waited_for_and_reused(tmp_path: Path) -> None:
    """``spawn_viewer`` returns once the viewer listens; a second call finds it and starts no other.

    The viewer here is the real binary made headless (``--save``) by a wrapper script that notes its pid,
    since this machine has no display for the window ``--rerun-spawn`` normally opens.
    """
    import os
    import signal

    from monitor.service.live_sinks import spawn_viewer, viewer_answers
    from tests.rerun_viewer import viewer_binary

    port, pid_file = free_tcp_port(), tmp_path / "viewer.pid"
    script = tmp_path / "rerun"
    script.write_text(f'#!/bin/sh\necho $$ >> "{pid_file}"\nexec "{viewer_binary()}" "$@" --save "{tmp_path}/s.rrd"\n')
    script.chmod(0o755)
    try:
        url = spawn_viewer(str(script), port)
        assert url == f"rerun+http://127.0.0.1:{port}/proxy" and viewer_answers("127.0.0.1", port)
        assert spawn_viewer(str(script), port) == url
        assert len(pid_file.read_text().split()) == 1, "a second viewer was started"
    finally:
        for pid in pid_file.read_text().split() if pid_file.exists() else []:
            try:
                os.killpg(int(pid), signal.SIGTERM)  # its own session: the group is the viewer
            except ProcessLookupError:
                pass
