"""A JSBSim aircraft behind a link that delays every command by 1 to 2.4 samples, in calm air.

An identified 4-state c172p model (``tests/data/c172p-longitudinal-long-delay.toml``, tau in [0.05, 0.12] s at
h = 0.05 s) is designed for and certified by the README's commands; the monitor closes the loop on the nonlinear
aircraft (``sim-vehicle --aircraft c172p --delay uniform:0.05:0.12``) with a 2 deg elevator bias. Judged against
the vehicle's truth stream: f_hat within 5 % of the bias from 1 s after onset, no alarm before it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.ahead import LONG_DELAY_PLANT, designed_ahead
from tests.e2e.aircraft_loop import RATE, fly

PLANT = LONG_DELAY_PLANT
ONSET, BIAS = 100, 2.0
STEPS = ONSET + 11 * RATE  # 5 s before the bias, 11 s after it


def test_a_jsbsim_aircraft_with_commands_one_to_two_and_a_half_samples_late(tmp_path: Path) -> None:
    # the README's design and verify of the plant, run ahead of the test at a low priority (tests/ahead.py)
    gains = tmp_path / "gains.toml"
    design, verify = designed_ahead("long-delay", gains)
    assert "delay      past one sample" in design.stdout, design.stdout
    assert verify.returncode == 0 and "certificate                      valid" in verify.stdout, verify.stdout
    flight = fly(
        tmp_path,
        PLANT,
        gains,
        design.stdout,
        STEPS,
        "--delay",
        "uniform:0.05:0.12",
        "--fault",
        f"bias:{BIAS:g}@{ONSET}",
    )
    acted = [p["tau"] for p in flight.truth if p["tau"] is not None]
    assert len(acted) > 0.9 * STEPS and min(acted) >= 0.05 and max(acted) > 0.1  # one to 2.4 samples late
    errors = flight.errors(ONSET + RATE, STEPS)
    assert len(errors) >= 0.95 * (STEPS - ONSET - RATE)
    assert np.max(np.abs(errors)) <= 0.05 * BIAS, f"|e_f| up to {np.max(np.abs(errors)):.3f} from 1 s after onset"
    raised = flight.alarms()
    assert raised and min(raised) >= ONSET, f"alarms at k = {raised}: none may precede the onset {ONSET}"
    assert max(abs(flight.f_hat[k]) for k in range(ONSET) if k in flight.f_hat) < 0.25 * BIAS
