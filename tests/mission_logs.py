"""A mission flown by ``sim-vehicle --aircraft`` on its own autopilot and logged as a ground station would (every
datagram into a tlog), for the tests that read manoeuvres with ``analyse`` and ``benchmarks/mission_envelope.py``;
and the mission's segments in time. Loopback only; every wait bounded."""

from __future__ import annotations

import select
import socket
import time
from pathlib import Path

from monitor.link.tlog import TlogWriter
from sim_vehicle.mission import load_mission
from tests.daemons import Daemon


def log_mission(
    tmp_path: Path,
    mission: Path,
    *extra: str,
    aircraft: str = "c172p",
    name: str = "mission",
    budget_s: float = 90.0,
    speedup: str = "1e4",
) -> Path:
    """``mission`` flown at ``speedup`` (by default as fast as JSBSim goes; ``extra``: more sim-vehicle options,
    e.g. a fault), into ``tmp_path/NAME.tlog``."""
    tlog = tmp_path / f"{name}.tlog"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock, TlogWriter(tlog) as writer:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        args = ["run", "--aircraft", aircraft, "--mission", str(mission), "--speedup", speedup, "--no-zenoh", *extra]
        with Daemon("sim_vehicle", [*args, "--mavlink", f"udpout:127.0.0.1:{port}"], tmp_path / f"{name}.log") as d:
            deadline = time.monotonic() + budget_s
            quiet_until = None
            while time.monotonic() < deadline:
                ready, _, _ = select.select([sock], [], [], 0.1)
                if ready:
                    writer.write_datagram(time.time_ns() // 1000, sock.recv(65535))
                    continue
                if d.proc is not None and d.proc.poll() is not None:
                    quiet_until = quiet_until or time.monotonic() + 0.3
                    if time.monotonic() > quiet_until:
                        break
            assert d.wait(10) == 0, d.log()[-3000:]
    return tlog


def segments(mission: Path) -> list[tuple[str, float, float]]:
    """(name, start s, end s) of each segment, from the vehicle's first sample, as sim-vehicle reads the file."""
    return [(s.name, s.start, s.start + s.duration) for s in load_mission(mission).segments]


def legs(mission: Path) -> list[tuple[str, float, float]]:
    """The identification legs (the segments with ``excite``) of ``mission``, as :func:`segments` gives them."""
    return [(s.name, s.start, s.start + s.duration) for s in load_mission(mission).segments if s.excite is not None]
