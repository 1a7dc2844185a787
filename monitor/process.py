"""Stopping a daemon we started: SIGTERM, a bounded wait, then SIGKILL to its whole process group.

Shared by the demo (which starts `sim-vehicle` and `fault-monitor run`) and the tests, so that every
process started in its own session is stopped the same way and no wait is unbounded.
"""

from __future__ import annotations

import os
import signal
import subprocess

__all__ = ["stop_process_group"]


def stop_process_group(proc: subprocess.Popen, timeout: float = 15.0) -> int:
    """Ask ``proc`` to stop (SIGTERM); after ``timeout`` s kill its process group. Returns the exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)
    return proc.returncode
