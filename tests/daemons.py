"""Helpers for tests that start real daemons: free loopback ports, bounded waits, guaranteed stop.

Every process started through ``Daemon`` is stopped when the ``with`` block ends (SIGTERM, then SIGKILL
after a bounded wait), whatever the test did, so a failing test never leaves a daemon behind.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from monitor.process import stop_process_group

REPO = Path(__file__).resolve().parent.parent


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(predicate: Callable[[], bool], timeout: float, interval: float = 0.05, what: str = "condition") -> None:
    """Poll ``predicate`` until true; fail the test after ``timeout`` seconds (every wait is bounded)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout:.1f} s waiting for {what}")


class Daemon:
    """A console script run as ``python -m <module> ...`` in its own process group, stopped on exit."""

    def __init__(self, module: str, args: list[str], log_path: Path, env: dict[str, str] | None = None) -> None:
        self.cmd = [sys.executable, "-m", module, *args]
        self.log_path = log_path
        self.env = {**os.environ, "RERUN_ANALYTICS": "0", **(env or {})}
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> Daemon:
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            self.cmd,
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=self.env,
            cwd=REPO,
            start_new_session=True,
        )
        return self

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def signal(self, sig: int = signal.SIGTERM) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.send_signal(sig)

    def wait(self, timeout: float) -> int:
        assert self.proc is not None
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{self.cmd[2]} did not exit within {timeout} s; log:\n{self.log()[-3000:]}") from None

    def stop(self, timeout: float = 10.0) -> int | None:
        return None if self.proc is None else stop_process_group(self.proc, timeout)

    def __exit__(self, *exc) -> None:
        try:
            self.stop()
        finally:
            self._log.close()
