"""The monitor's end-to-end rig, shared by the tests that run ``fault-monitor run`` and ``sim-vehicle`` as daemons:
a Zenoh router session owned by the test (``Bus``, ``zenoh_bus``: the daemons are its clients, since in Zenoh 1.10
two peers linked only through a router do not see each other's publications with gossip off), the daemon starters
(``monitor_daemon``, ``sim_daemon``), and the readings of a run (``wait_ready``, ``processed_count``,
``settling_k``).

Why a module of its own: these used to live in ``tests/e2e/test_monitor_paper.py``, and a dozen test modules
imported them (and its fixture) from a test module. A plain module, no tests and no fixtures, is the one copy;
the certified ``gains_file`` these tests fly with is a fixture in ``tests/conftest.py``.
"""

from __future__ import annotations

import json
import re
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.daemons import Daemon, free_tcp_port, wait_for


class Bus:
    """A Zenoh router session owned by the test, and JSON collectors on it."""

    def __init__(self) -> None:
        from monitor.wire.zenoh_session import build_config, open_session

        self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        self.session = open_session(build_config(listen=[self.endpoint], mode="router"))
        self._subs: list = []

    def collect(self, keyexpr: str) -> list[dict]:
        got: list[dict] = []
        lock = threading.Lock()

        def on_sample(sample) -> None:
            with lock:
                got.append(json.loads(sample.payload.to_bytes()))

        self._subs.append(self.session.declare_subscriber(keyexpr, on_sample))
        return got

    def query(self, keyexpr: str) -> list[tuple[str, dict]]:
        out = []
        for reply in self.session.get(keyexpr, timeout=3.0):
            if reply.ok is not None:
                out.append((str(reply.ok.key_expr), json.loads(reply.ok.payload.to_bytes())))
        return out

    def tokens(self, keyexpr: str) -> list[str]:
        return [str(r.ok.key_expr) for r in self.session.liveliness().get(keyexpr, timeout=3.0) if r.ok is not None]

    def close(self) -> None:
        from monitor.wire.zenoh_session import close_quietly

        close_quietly(self.session, *self._subs)


@contextmanager
def zenoh_bus() -> Iterator[Bus]:
    bus = Bus()
    try:
        yield bus
    finally:
        bus.close()


def monitor_daemon(tmp_path: Path, gains: Path, port: int, bus: Bus, name: str, *extra: str) -> Daemon:
    args = [
        "run",
        "--plant",
        "paper-continuous",
        "--gains",
        str(gains),
        "--mavlink",
        f"udpin:127.0.0.1:{port}",
        "--zenoh-mode",
        "client",
        "--zenoh-connect",
        bus.endpoint,
        "--name",
        name,
        *extra,
    ]
    return Daemon("monitor", args, tmp_path / f"{name}.log")


def sim_daemon(
    tmp_path: Path, port: int, bus: Bus, sysid: int, *extra: str, steps: int = 60, speedup: float = 25
) -> Daemon:
    args = [
        "run",
        "--sysid",
        str(sysid),
        "--steps",
        str(steps),
        "--speedup",
        str(speedup),
        "--mavlink",
        f"udpout:127.0.0.1:{port}",
        "--zenoh-mode",
        "client",
        "--zenoh-connect",
        bus.endpoint,
        *extra,
    ]
    return Daemon("sim_vehicle", args, tmp_path / f"sim{sysid}-{port}.log")


def wait_ready(monitor: Daemon) -> None:
    wait_for(lambda: "ready:" in monitor.log() or monitor.proc.poll() is not None, 20, what="monitor ready")
    assert "ready:" in monitor.log(), monitor.log()


def processed_count(log: str) -> int:
    match = re.search(r"samples processed (\d+)", log)
    assert match, log[-2000:]
    return int(match.group(1))


def shed_count(log: str) -> int:
    """The summary's samples shed under overload (not answered: lost samples to the estimator)."""
    match = re.search(r"[ ,]shed (\d+)", log)
    assert match, log[-2000:]
    return int(match.group(1))


def settling_k(estimates: list[dict], truth: float, tol: float) -> int | None:
    """First k from which |f_hat - truth| <= tol holds for every later estimate."""
    ordered = sorted(estimates, key=lambda e: e["k"])
    settled = None
    for e in ordered:
        if abs(e["f_hat"][0] - truth) <= tol:
            settled = e["k"] if settled is None else settled
        else:
            settled = None
    return settled
