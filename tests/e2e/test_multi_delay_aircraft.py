"""A JSBSim aircraft behind a link that delays every command by 1 to 2.4 samples, in calm air.

An identified 4-state c172p model (``tests/data/c172p-longitudinal-long-delay.toml``, tau in [0.05, 0.12] s at
h = 0.05 s) is designed for and certified by the README's commands; the monitor closes the loop on the nonlinear
aircraft (``sim-vehicle --aircraft c172p --delay uniform:0.05:0.12``) with a 2 deg elevator bias. Judged against
the vehicle's truth stream: f_hat within 5 % of the bias from 1 s after onset, no alarm before it.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.daemons import Daemon, free_tcp_port, free_udp_port
from tests.e2e.test_monitor_paper import wait_ready

PLANT = str(Path(__file__).parents[1] / "data" / "c172p-longitudinal-long-delay.toml")
RATE, ONSET, BIAS = 20, 100, 2.0
STEPS = ONSET + 21 * RATE  # 5 s before the bias, 21 s after it


def test_a_jsbsim_aircraft_with_commands_one_to_two_and_a_half_samples_late(tmp_path: Path) -> None:
    from monitor.api import read_recording

    gains = tmp_path / "gains.toml"
    for argv in (["design", "--plant", PLANT, "--out", str(gains)], ["verify", "--plant", PLANT, "--gains", str(gains)]):
        done = subprocess.run([sys.executable, "-m", "monitor", *argv], capture_output=True, text=True, timeout=240)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "certificate                      valid" in done.stdout, done.stdout
    port, rrd, truth = free_udp_port(), tmp_path / "run.rrd", tmp_path / "truth.jsonl"
    monitor = Daemon("monitor", ["run", "--plant", PLANT, "--gains", str(gains), "--mavlink", f"udpin:127.0.0.1:{port}",
                                 "--zenoh-listen", f"tcp/127.0.0.1:{free_tcp_port()}", "--rrd", str(rrd)],
                     tmp_path / "monitor.log")
    with monitor:
        wait_ready(monitor)
        vehicle = Daemon("sim_vehicle", ["run", "--aircraft", "c172p", "--airspeed", "100", "--altitude", "3000",
                                         "--rate", str(RATE), "--steps", str(STEPS), "--delay", "uniform:0.05:0.12",
                                         "--fault", f"bias:{BIAS:g}@{ONSET}", "--speedup", "3", "--mavlink",
                                         f"udpout:127.0.0.1:{port}", "--no-zenoh", "--truth-jsonl", str(truth)],
                         tmp_path / "vehicle.log")
        with vehicle:
            assert vehicle.wait(120) == 0, vehicle.log()[-3000:]
        monitor.signal()
        assert monitor.wait(30) == 0, monitor.log()[-3000:]
    payloads = [json.loads(line) for line in truth.read_text().splitlines()]
    acted = [p["tau"] for p in payloads if p["tau"] is not None]
    assert len(acted) > 0.9 * STEPS and min(acted) >= 0.05 and max(acted) > 0.1  # one to 2.4 samples late
    truth_f = {p["k"]: float(p["f"][0]) for p in payloads}
    f_hat = {r.k: float(np.ravel(r.f_hat)[0]) for r in read_recording(rrd).vehicles[1].samples}
    judged = [k for k in range(ONSET + RATE, STEPS) if k in f_hat]
    assert len(judged) >= 0.95 * (STEPS - ONSET - RATE)
    errors = np.array([f_hat[k] - truth_f[k] for k in judged])
    assert np.max(np.abs(errors)) <= 0.05 * BIAS, f"|e_f| up to {np.max(np.abs(errors)):.3f} from 1 s after onset"
    raised = [int(k) for k in re.findall(r"alarm raised at k=(\d+)", monitor.log())]
    assert raised and min(raised) >= ONSET, f"alarms at k = {raised}: none may precede the onset {ONSET}"
    assert max(abs(f_hat[k]) for k in range(ONSET) if k in f_hat) < 0.25 * BIAS
