"""MAVProxy as a router in a test, shared by the end-to-end tests that route through it (``test_mavproxy``,
``test_sim_aircraft``, ``test_aircraft_chain``): ``MavProxy`` runs it headless between a master port and an
output, writing a tlog, and ``tlog_counts`` counts what that tlog holds per message and system id.
"""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from monitor.process import udp_port_taken
from tests.daemons import Daemon, wait_for


def _mavproxy_script() -> str:
    script = Path(sys.executable).with_name("mavproxy.py")
    if not script.exists():
        pytest.fail("mavproxy.py not found beside the interpreter: install the test extra (pip install '.[test]')")
    return str(script)


class MavProxy(Daemon):
    """Headless MAVProxy routing ``master`` (where the vehicle sends) to the monitor (``out``, and ``more_outs`` for
    a monitor group: every output gets every message), writing a tlog."""

    def __init__(
        self, tmp_path: Path, master: int, out: int, out_kind: str = "udpout", more_outs: tuple[int, ...] = ()
    ) -> None:
        super().__init__("x", [], tmp_path / "mavproxy.log")
        self.tlog = tmp_path / "mavproxy.tlog"
        self.master = master
        self.cmd = [
            sys.executable,
            _mavproxy_script(),
            f"--master=udpin:127.0.0.1:{master}",
            *(f"--out={out_kind}:127.0.0.1:{port}" for port in (out, *more_outs)),  # one output per monitor
            "--daemon",
            "--mav20",
            "--dialect=ardupilotmega",
            f"--state-basedir={tmp_path}",
            f"--logfile={self.tlog}",
            "--default-modules=",
            "--nowait",
            "--cmd=set flushlogs True",
        ]  # else the tlog tail sits in a buffer a signal may never write

    def __enter__(self) -> MavProxy:
        super().__enter__()
        wait_for(lambda: udp_port_taken(self.master) or self.proc.poll() is not None, 30, what="MAVProxy listening")
        assert self.proc.poll() is None, self.log()
        return self

    def stop(self, timeout: float = 10.0):
        import signal

        self.signal(signal.SIGINT)  # MAVProxy closes its log on SIGINT
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            pass
        return super().stop(timeout)


def tlog_counts(path: Path) -> Counter:
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    counts: Counter = Counter()
    while (msg := log.recv_match(blocking=False)) is not None:
        name = msg.get_type()
        if name == "NAMED_VALUE_FLOAT":
            name += ":" + msg.name
        counts[(name, msg.get_srcSystem())] += 1
    return counts
