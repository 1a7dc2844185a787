"""Daemons we start: is one listening yet, and stopping it (SIGTERM, a bounded wait, then SIGKILL).

Shared by the demo (which starts `sim-vehicle` and `fault-monitor run`) and the tests, so that every
process started in its own session is watched and stopped the same way and no wait is unbounded.
"""

from __future__ import annotations

import errno
import os
import signal
import socket
import subprocess

__all__ = ["stop_process_group", "udp_port_taken"]


def udp_port_taken(port: int, host: str = "127.0.0.1") -> bool:
    """True once something is bound to the UDP port: how a starter knows a daemon (or MAVProxy) listens."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((host, port))
        except OSError as exc:
            return exc.errno == errno.EADDRINUSE
        return False


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
