"""A delay of one to 2.4 samples end to end, with the README's own blocks (group ``long-delay``).

The README's commands design and verify the lagged plant (``docs/examples/paper-continuous-long-delay.toml``),
run ``fault-monitor run`` and ``sim-vehicle run`` as daemons on loopback (``tests/readme_blocks.py``: free ports,
the flight shortened), and replay the recording. The vehicle applies each command when it arrives, as many
samples late as drawn. Judged on what crossed the wire: the truth the vehicle published over Zenoh (recorded
beside the estimates) against the estimates, matched by sample index, and on the replay's report.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from tests.daemons import REPO
from tests.monitor_bus import processed_count, shed_count
from tests.readme_blocks import Session, group

STEPS, ONSET, BIAS = 60, 20, 2.0


def test_the_readme_long_delay_blocks_estimate_and_hold(tmp_path: Path) -> None:
    from monitor.api import read_recording

    flight, replay = group("long-delay")
    with Session(tmp_path, steps=STEPS, speedup=20) as s:
        shutil.copytree(REPO / "docs" / "examples", s.dir / "docs" / "examples")  # the user is in a clone
        design, verify, monitor, vehicle = s.run(flight)
        assert "certificate" in design.out() and "delay      past one sample" in design.out(), design.failure("")
        assert "STABLE" in verify.out() and "certificate                      valid" in verify.out(), verify.failure("")
        s.stop()  # Ctrl-C: the monitor writes its recording's footer
        # every sample answered or, on a machine too slow to keep up at 20x (a stall when the vehicle is first
        # heard), shed: a lost sample to the estimator, at most two
        processed, shed = processed_count(monitor.err()), shed_count(monitor.err())
        assert processed + shed == STEPS and shed <= 2, monitor.failure("not every sample answered or shed")
        (report,) = s.run(replay)
        out = report.out()
        assert f"{processed} samples" in out and "(from the recorded truth)" in out, report.failure("")
        s.assert_ran_all("long-delay")
        series = read_recording(s.dir / "long-delay.rrd").vehicles[1]
    truth = {r.k: r for r in series.truth}
    f_hat = {r.k: float(np.ravel(r.f_hat)[0]) for r in series.samples}
    assert len(truth) >= STEPS - 2 and len(f_hat) == processed
    acted = [r.tau for r in truth.values() if r.tau is not None]
    assert len(acted) > 0.8 * STEPS and min(acted) >= 1.0 and max(acted) > 2.0, acted  # all a sample or more late
    errors = [abs(f_hat[k] - truth[k].f[0]) for k in range(ONSET + 6, STEPS) if k in truth and k in f_hat]
    assert max(errors) <= 0.05 * BIAS, max(errors)  # within 5 % of the fault from 6 samples after onset
    assert max(abs(f_hat[k]) for k in range(ONSET) if k in f_hat) < 0.05 * BIAS  # nothing before it
    assert max(abs(r.x[0]) for r in truth.values()) < 2.0  # the loop holds: alpha stays within 2 deg
