"""A 2 deg elevator bias seen through JSBSim's light turbulence, with the README's commands.

``fault-monitor design`` on an identified c172p model that carries its air (a ``[disturbance]`` table) gives the
default design, whose reported f_hat is low-passed with a 1-s time constant; the monitor closes the loop on the nonlinear
aircraft in light MIL-F-8785C turbulence. Judged against the vehicle's truth: 30 s before the onset without an
alarm, the bias detected within 2 s, and |e_f| RMS <= 0.3 deg from 2 s after onset.
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

PLANT = str(Path(__file__).parents[1] / "data" / "c172p-longitudinal-turbulence.toml")
RATE, ONSET, BIAS = 20, 600, 2.0  # the bias 30 s into the flight
STEPS = ONSET + 20 * RATE


def test_a_bias_through_light_turbulence_no_false_alarm_detected_within_two_seconds(tmp_path: Path) -> None:
    from monitor.api import read_recording

    gains = tmp_path / "gains.toml"
    done = subprocess.run([sys.executable, "-m", "monitor", "design", "--plant", PLANT, "--out", str(gains)],
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "low-passed with a 1-s time constant" in done.stdout, done.stdout  # the default for a plant with its air
    port, rrd, truth = free_udp_port(), tmp_path / "run.rrd", tmp_path / "truth.jsonl"
    monitor = Daemon("monitor", ["run", "--plant", PLANT, "--gains", str(gains), "--mavlink", f"udpin:127.0.0.1:{port}",
                                 "--zenoh-listen", f"tcp/127.0.0.1:{free_tcp_port()}", "--rrd", str(rrd)],
                     tmp_path / "monitor.log")
    with monitor:
        wait_ready(monitor)
        vehicle = Daemon("sim_vehicle", ["run", "--aircraft", "c172p", "--airspeed", "100", "--altitude", "3000",
                                         "--rate", str(RATE), "--turbulence", "light", "--steps", str(STEPS),
                                         "--fault", f"bias:{BIAS:g}@{ONSET}", "--speedup", "3", "--seed", "21",
                                         "--mavlink", f"udpout:127.0.0.1:{port}", "--no-zenoh", "--truth-jsonl",
                                         str(truth)], tmp_path / "vehicle.log")
        with vehicle:
            assert vehicle.wait(120) == 0, vehicle.log()[-3000:]
        monitor.signal()
        assert monitor.wait(30) == 0, monitor.log()[-3000:]
    raised = [int(k) for k in re.findall(r"alarm raised at k=(\d+)", monitor.log())]
    assert raised and min(raised) >= ONSET, f"alarms at k = {raised}: a false alarm before the onset at {ONSET}"
    assert min(raised) <= ONSET + 2 * RATE, f"the bias detected {(min(raised) - ONSET) / RATE:g} s after onset"
    truth_f = {p["k"]: float(p["f"][0]) for p in map(json.loads, truth.read_text().splitlines())}
    f_hat = {r.k: float(np.ravel(r.f_hat)[0]) for r in read_recording(rrd).vehicles[1].samples}
    judged = [k for k in range(ONSET + 2 * RATE, STEPS) if k in f_hat]
    assert len(judged) >= 0.95 * (STEPS - ONSET - 2 * RATE)
    rms = float(np.sqrt(np.mean([(f_hat[k] - truth_f[k]) ** 2 for k in judged])))
    assert rms <= 0.3, f"|e_f| RMS {rms:.3f} deg from 2 s after onset"
    print(f"first alarm {(min(raised) - ONSET) / RATE:g} s after onset; |e_f| RMS {rms:.3f} deg; peak |f_hat| before "
          f"onset {max(abs(f_hat[k]) for k in range(ONSET) if k in f_hat):.3f} deg")
