"""A 2 deg elevator bias seen through JSBSim's light turbulence, with the README's commands.

``fault-monitor design`` on an identified c172p model that carries its air (a ``[disturbance]`` table naming the
light level) gives the default design, whose reported f_hat is low-passed with a 1-s time constant; the monitor
closes the loop on the nonlinear aircraft in light MIL-F-8785C turbulence. Judged against the vehicle's truth:
30 s before the onset without an alarm, the bias detected within 2 s, |e_f| RMS <= 0.3 deg from 2 s after onset.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.ahead import TURBULENCE_PLANT, designed_ahead
from tests.e2e.aircraft_loop import RATE, fly

PLANT = TURBULENCE_PLANT
ONSET, BIAS = 600, 2.0  # the bias 30 s into the flight
STEPS = ONSET + 20 * RATE


def test_a_bias_through_light_turbulence_no_false_alarm_detected_within_two_seconds(tmp_path: Path) -> None:
    # the README's design of the plant, run ahead of the test at a low priority (tests/ahead.py)
    gains = tmp_path / "gains.toml"
    (design,) = designed_ahead("turbulence", gains)
    flight = fly(
        tmp_path,
        PLANT,
        gains,
        design.stdout,
        STEPS,
        "--turbulence",
        "light",
        "--seed",
        "21",
        "--fault",
        f"bias:{BIAS:g}@{ONSET}",
    )
    assert "low-passed with a 1-s time constant" in flight.design_out, flight.design_out  # the default in turbulence
    raised = flight.alarms()
    assert raised and min(raised) >= ONSET, f"alarms at k = {raised}: a false alarm before the onset at {ONSET}"
    assert min(raised) <= ONSET + 2 * RATE, f"the bias detected {(min(raised) - ONSET) / RATE:g} s after onset"
    errors = flight.errors(ONSET + 2 * RATE, STEPS)
    assert len(errors) >= 0.95 * (STEPS - ONSET - 2 * RATE)
    rms = float(np.sqrt(np.mean(errors**2)))
    assert rms <= 0.3, f"|e_f| RMS {rms:.3f} deg from 2 s after onset"
