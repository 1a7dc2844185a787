"""An envelope designed on a real Dask cluster: a ``dask scheduler`` and a ``dask worker`` started as processes of
their own on loopback (as on other machines, with this package installed), ``fault-monitor design --scheduler``
sending the points to them; the gains equal those of the design in this process. The envelope is the small one of
``docs/explanation/envelope.md`` (two short-period points, a design in seconds): the test is about where the points
are designed, not their size. Every wait bounded; both processes stopped."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from monitor.gains import read_envelope_gains
from tests.daemons import REPO, Daemon, free_tcp_port
from tests.envelope_files import documented_envelope

pytestmark = [pytest.mark.slow, pytest.mark.daemons]


def design(tmp_path: Path, name: str, *extra: str) -> subprocess.CompletedProcess:
    envelope = tmp_path / "envelope.toml"
    envelope.write_text(documented_envelope())
    cmd = [sys.executable, "-m", "monitor", "design", "--plant", str(envelope), "--out", str(tmp_path / name), *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180, cwd=REPO)


def wait_for_port(port: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise AssertionError(f"nothing listens on 127.0.0.1:{port} after {timeout} s")


def test_the_points_are_designed_on_the_cluster_at_the_scheduler_address(tmp_path: Path) -> None:
    port = free_tcp_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--dashboard-address", "127.0.0.1:0"]
    worker = ["worker", address, "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "1", "--no-dashboard"]
    with Daemon("dask", scheduler, tmp_path / "scheduler.log") as sched:
        wait_for_port(port, 30.0)
        with Daemon("dask", worker, tmp_path / "worker.log", env={"OMP_NUM_THREADS": "1"}):
            remote = design(tmp_path, "remote.toml", "--scheduler", address)
        assert remote.returncode == 0, remote.stderr[-3000:] + sched.log()[-2000:]
    assert f"on the Dask cluster at {address}" in remote.stderr
    local = design(tmp_path, "local.toml", "--jobs", "1", "--quiet")
    assert local.returncode == 0, local.stderr
    a, b = read_envelope_gains(tmp_path / "remote.toml"), read_envelope_gains(tmp_path / "local.toml")
    assert list(a.points) == list(b.points)
    for name in a.points:  # the same design, wherever it ran (the same solver on the same problem)
        for key in ("L", "M", "K1", "K2", "K3"):
            assert np.allclose(getattr(a.points[name].gains, key), getattr(b.points[name].gains, key), atol=1e-6)


def test_a_scheduler_that_does_not_answer_is_one_line(tmp_path: Path, monkeypatch) -> None:
    import monitor.parallel
    from monitor.errors import UserError
    from monitor.parallel import run_tasks

    monkeypatch.setattr(monitor.parallel, "CONNECT_TIMEOUT_S", 1.0)  # the command waits 10 s
    address = f"tcp://127.0.0.1:{free_tcp_port()}"  # nothing listens there
    with pytest.raises(UserError) as err:
        run_tasks(abs, [("a", (-1,))], 2, lambda *_: None, scheduler=address)
    assert str(err.value).startswith(f"--scheduler {address}: no Dask scheduler answered within 1 s")
    assert "\n" not in str(err.value)
