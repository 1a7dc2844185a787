"""One live run of the paper scenario: real `sim-vehicle` and `fault-monitor run` daemons on loopback.

The demo's own process is the Zenoh meeting point (a router session): it listens on a free loopback TCP port, both
daemons connect to it as clients (no zenohd, no multicast), and it subscribes to the estimates and the ground truth to
show progress. The scores come from the monitor's .rrd recording (the same code as `fault-monitor replay`),
so what the table says can be recomputed from the files it leaves behind.

Every daemon is started in its own process group and stopped in a ``finally`` (SIGTERM, then SIGKILL after
a bounded wait); every wait has a deadline.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from monitor.errors import UserError
from monitor.process import stop_process_group, udp_port_taken

__all__ = ["Aircraft", "Scenario", "LiveRun", "Daemon", "run_live", "free_port"]


@dataclass(frozen=True)
class Aircraft:
    """A JSBSim aircraft for ``sim-vehicle run --aircraft`` and its flight condition."""

    name: str = "c172p"
    airspeed: float = 100.0  # kt
    altitude: float = 3000.0  # ft
    rate: float = 20.0  # Hz: h = 1 / rate
    turbulence: str = "none"
    aircraft_dir: str | None = None

    def vehicle_args(self) -> list[str]:
        """sim-vehicle's flags that fly this aircraft at this condition."""
        args = [
            "--aircraft",
            self.name,
            "--airspeed",
            f"{self.airspeed:g}",
            "--altitude",
            f"{self.altitude:g}",
            "--rate",
            f"{self.rate:g}",
            "--turbulence",
            self.turbulence,
        ]
        return args + (["--aircraft-dir", self.aircraft_dir] if self.aircraft_dir else [])


@dataclass(frozen=True)
class Scenario:
    """What every design is run against (the paper's, by default).

    With ``aircraft`` the vehicle flies that JSBSim aircraft (``wind`` does not apply: its air is the
    aircraft's ``turbulence``) and ``plant`` is only the monitor's model of it.
    """

    plant: str = "paper-continuous"
    steps: int = 100
    speedup: float = 10.0
    fault: str = "bias:2@20"
    delay: str = "uniform:0:0.46"
    wind: str = "paper"
    seed: int = 0
    sysid: int = 1
    aircraft: Aircraft | None = None

    def vehicle_args(self) -> list[str]:
        """sim-vehicle's flags for the vehicle flown: the aircraft, or the plant and its wind."""
        if self.aircraft is not None:
            return self.aircraft.vehicle_args()
        return ["--plant", self.plant, "--wind", self.wind]

    def wall_budget(self) -> float:
        """Seconds the vehicle may take to fly ``steps`` at ``speedup``, with room for start-up (the paper's h
        is 1 s)."""
        h = 1.0 / self.aircraft.rate if self.aircraft is not None else 1.0
        return self.steps * h / self.speedup + 30.0


@dataclass
class LiveRun:
    method: str
    rrd: Path
    log_dir: Path
    estimates: list[dict] = field(default_factory=list)
    truth: list[dict] = field(default_factory=list)
    sim_exit: int | None = None
    monitor_exit: int | None = None
    wall_seconds: float = 0.0


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(
    predicate: Callable[[], bool],
    timeout: float,
    what: str,
    proc: subprocess.Popen | None = None,
    log: Path | None = None,
) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        if proc is not None and proc.poll() is not None:
            tail = log.read_text(errors="replace")[-800:] if log and log.exists() else ""
            raise UserError(f"{what}: the process exited with code {proc.returncode}; log tail: {tail.strip()}")
        time.sleep(0.05)
    raise UserError(f"timed out after {timeout:.0f} s waiting for {what}")


class Daemon:
    """A console entry point run with this interpreter, in its own process group, always stopped."""

    def __init__(self, module: str, args: list[str], log: Path) -> None:
        self.log = log
        self._fh = open(log, "wb")
        env = {**os.environ, "RERUN_ANALYTICS": "0"}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            stdout=self._fh,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )

    def stop(self, timeout: float = 15.0) -> int:
        code = stop_process_group(self.proc, timeout)
        self._fh.close()
        return code


def run_live(method: str, gains: Path, scenario: Scenario, out_dir: Path, progress: Callable[[str], None]) -> LiveRun:
    """Run one design live and return what the demo's subscriber saw (the recording is ``out_dir/<method>.rrd``;
    ``method`` is the run's label, which names its files)."""
    import zenoh

    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    zport, uport = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_DGRAM)
    endpoint = f"tcp/127.0.0.1:{zport}"
    run = LiveRun(method=method, rrd=out_dir / f"{method}.rrd", log_dir=out_dir / "logs")
    run.log_dir.mkdir(parents=True, exist_ok=True)
    run.rrd.unlink(missing_ok=True)
    lock = threading.Lock()

    def collect(into: list[dict]) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                payload = json.loads(sample.payload.to_bytes())
            except ValueError:
                return
            with lock:
                into.append(payload)

        return on_sample

    # A router with both daemons as its clients: peers that only know a hub (gossip and multicast off) do not
    # see each other's publications through it, clients of a router do (the monitor needs the truth stream).
    session = open_session(build_config(listen=[endpoint], mode="router"))
    subs = [
        session.declare_subscriber(f"uav/{scenario.sysid}/fault/estimate", collect(run.estimates)),
        session.declare_subscriber(f"uav/{scenario.sysid}/truth", collect(run.truth)),
    ]
    monitor = sim = None
    t0 = time.monotonic()
    try:
        name = f"demo-{method}-{os.getpid()}"
        monitor = Daemon(
            "monitor",
            [
                "--log-level",
                "INFO",
                "run",
                "--plant",
                scenario.plant,
                "--gains",
                str(gains),
                "--mavlink",
                f"udpin:127.0.0.1:{uport}",
                "--zenoh-connect",
                endpoint,
                "--zenoh-mode",
                "client",
                "--rrd",
                str(run.rrd),
                "--name",
                name,
            ],
            run.log_dir / f"{method}-monitor.log",
        )
        token = f"uav/monitor/{name}"
        _wait(
            lambda: any(True for _ in session.liveliness().get(token, timeout=0.2)),
            60,
            f"monitor '{name}' on Zenoh",
            monitor.proc,
            monitor.log,
        )
        _wait(lambda: udp_port_taken(uport), 20, f"monitor UDP port {uport}", monitor.proc, monitor.log)
        sim = Daemon(
            "sim_vehicle",
            [
                "run",
                *scenario.vehicle_args(),
                "--mavlink",
                f"udpout:127.0.0.1:{uport}",
                "--sysid",
                str(scenario.sysid),
                "--steps",
                str(scenario.steps),
                "--speedup",
                str(scenario.speedup),
                "--fault",
                scenario.fault,
                "--delay",
                scenario.delay,
                "--seed",
                str(scenario.seed),
                "--zenoh-connect",
                endpoint,
                "--zenoh-mode",
                "client",
                "--log-level",
                "INFO",
            ],
            run.log_dir / f"{method}-sim.log",
        )
        budget = scenario.wall_budget()
        deadline = time.monotonic() + budget
        while sim.proc.poll() is None:
            if time.monotonic() > deadline:
                raise UserError(f"sim-vehicle did not finish {scenario.steps} samples within {budget:.0f} s")
            with lock:
                k = run.estimates[-1]["k"] if run.estimates else -1
            progress(f"{method:<15} live: sample {k + 1:>4}/{scenario.steps}")
            time.sleep(0.25)
        run.sim_exit = sim.stop()
        sim = None
        linger = time.monotonic() + 3.0  # let the last estimates cross Zenoh before stopping the monitor
        while time.monotonic() < linger and not (
            run.estimates and run.estimates[-1].get("k", -1) >= scenario.steps - 1
        ):
            time.sleep(0.05)
    finally:
        if sim is not None:
            run.sim_exit = sim.stop()
        if monitor is not None:
            run.monitor_exit = monitor.stop()
        close_quietly(session, *subs)
    run.wall_seconds = time.monotonic() - t0
    if run.monitor_exit != 0:
        raise UserError(
            f"fault-monitor run ({method}) exited with {run.monitor_exit}; see {run.log_dir}/{method}-monitor.log"
        )
    if not run.rrd.exists():
        raise UserError(f"fault-monitor run ({method}) wrote no recording at {run.rrd}")
    return run
