"""A headless Rerun viewer for the tests that stream to one: the live viewer end to end
(``tests/e2e/test_live_viewer.py``) and the live sink alone (``tests/test_live_sinks.py``).

``viewer_binary`` is the real viewer (not the venv's Python wrapper, whose child a signal would miss),
``headless_viewer`` runs it as ``rerun --save`` on a loopback port and always stops it, and ``load_when_complete``
reads its file back once the viewer's own threads have written the samples.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from monitor.errors import UserError
from monitor.process import stop_process_group
from monitor.service.live_sinks import viewer_answers
from tests.daemons import wait_for


def viewer_binary() -> str:
    """The real viewer binary: the ``rerun`` script in the venv is a Python wrapper whose child a signal to
    the wrapper would leave running."""
    import rerun_cli

    return str(Path(rerun_cli.__file__).parent / "rerun")


@contextmanager
def headless_viewer(tmp_path: Path, port: int, out: Path) -> Iterator[subprocess.Popen]:
    """``rerun --save OUT`` on loopback ``port``: stores whatever is streamed to it; always stopped."""
    log = open(tmp_path / f"viewer-{port}.log", "wb")
    proc = subprocess.Popen(
        [viewer_binary(), "--bind", "127.0.0.1", "--port", str(port), "--save", str(out)],
        stdin=subprocess.DEVNULL,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )
    try:
        wait_for(lambda: viewer_answers("127.0.0.1", port) or proc.poll() is not None, 15, what="viewer listening")
        assert proc.poll() is None, (tmp_path / f"viewer-{port}.log").read_text(errors="replace")
        yield proc
    finally:
        stop_process_group(proc, 5)
        log.close()


def load_when_complete(path: Path, samples: int, timeout: float = 10.0):
    """The viewer writes its file from its own threads: read it back once it holds ``samples`` samples."""
    from monitor.service.recording_reader import load_recording

    got = {}

    def complete() -> bool:
        try:
            got["rec"] = load_recording(path)
        except UserError:  # not written yet, or a chunk half-written
            return False
        vehicles = got["rec"].vehicles
        return 1 in vehicles and len(vehicles[1].samples) >= samples

    wait_for(complete, timeout, interval=0.2, what=f"{samples} samples in {path.name}")
    return got["rec"]
