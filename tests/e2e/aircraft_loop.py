"""One closed-loop flight of a JSBSim c172p against a real ``fault-monitor run``, as a user would fly it.

Shared by the e2e tests that judge the loop on the nonlinear aircraft (long delays, turbulence): gains from the
README's ``design`` through the CLI (``tests/ahead.py`` runs it), the monitor as a daemon on loopback,
``sim-vehicle --aircraft`` flying ``steps`` samples, the monitor stopped by a signal (its summary and a complete
recording), and the truth read back.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tests.daemons import Daemon, free_tcp_port, free_udp_port
from tests.monitor_bus import wait_ready

RATE = 20  # Hz: h = 0.05 s


@dataclass
class Flight:
    design_out: str  # what `fault-monitor design` printed
    monitor_log: str
    truth: list[dict]  # the vehicle's truth payloads, one per sample
    f_hat: dict[int, float]  # the recorded (reported) estimate by sample index

    def alarms(self) -> list[int]:
        """Samples at which the monitor raised its alarm."""
        return [int(k) for k in re.findall(r"alarm raised at k=(\d+)", self.monitor_log)]

    def errors(self, first: int, last: int) -> np.ndarray:
        """``f_hat - f`` over the samples ``first .. last - 1`` that were recorded."""
        truth_f = {p["k"]: float(p["f"][0]) for p in self.truth}
        return np.array([self.f_hat[k] - truth_f[k] for k in range(first, last) if k in self.f_hat])


def fly(tmp_path: Path, plant: str, gains: Path, design_out: str, steps: int, *vehicle_args: str) -> Flight:
    """One closed-loop c172p flight of ``steps`` samples at 3x with ``gains`` (``design_out``: what `design` printed
    when it wrote them)."""
    from monitor.api import read_recording

    port, rrd, truth = free_udp_port(), tmp_path / "run.rrd", tmp_path / "truth.jsonl"
    monitor = Daemon(
        "monitor",
        [
            "run",
            "--plant",
            plant,
            "--gains",
            str(gains),
            "--mavlink",
            f"udpin:127.0.0.1:{port}",
            "--zenoh-listen",
            f"tcp/127.0.0.1:{free_tcp_port()}",
            "--rrd",
            str(rrd),
        ],
        tmp_path / "monitor.log",
    )
    with monitor:
        wait_ready(monitor)
        vehicle = Daemon(
            "sim_vehicle",
            [
                "run",
                "--aircraft",
                "c172p",
                "--airspeed",
                "100",
                "--altitude",
                "3000",
                "--rate",
                str(RATE),
                "--steps",
                str(steps),
                "--speedup",
                "3",
                "--mavlink",
                f"udpout:127.0.0.1:{port}",
                "--no-zenoh",
                "--truth-jsonl",
                str(truth),
                *vehicle_args,
            ],
            tmp_path / "vehicle.log",
        )
        with vehicle:
            assert vehicle.wait(120) == 0, vehicle.log()[-3000:]
        monitor.signal()
        assert monitor.wait(30) == 0, monitor.log()[-3000:]
    samples = read_recording(rrd).vehicles[1].samples
    return Flight(
        design_out=design_out,
        monitor_log=monitor.log(),
        truth=[json.loads(line) for line in truth.read_text().splitlines()],
        f_hat={r.k: float(np.ravel(r.f_hat)[0]) for r in samples},
    )
