"""`fault-monitor threshold`: a proven bound on |f_hat| without a fault, checked against what the loop can reach."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from monitor.closed_loop import closed_loop, steady_state
from monitor.delay_model import b0_of_tau, tau_grid
from monitor.errors import UserError
from monitor.threshold import fault_threshold
from tests.designs import designed


@pytest.fixture(scope="module")
def fast():
    return designed("paper-continuous", "certified")


def _impulse_l1(plant, gains, tau: float) -> float:
    """Independent: sum of |impulse response d -> e_f| at a constant delay, straight from the loop matrices."""
    loop = closed_loop(plant, gains, b0_of_tau(plant, tau), steady=steady_state(plant, gains))
    x, total = loop.B[:, 0].copy(), 0.0
    for _ in range(3000):
        total += abs(float(loop.C_ef[0] @ x))
        x = loop.A @ x
    return total


def _worst_case_peak(plant, gains, rng, steps: int = 80) -> float:
    """|f_hat| at the end of a run whose d(k) takes the sign that maximises it, delays random (time-varying)."""
    steady = steady_state(plant, gains)
    taus = rng.uniform(plant.tau_min, plant.tau_max, steps)
    loops = [closed_loop(plant, gains, b0_of_tau(plant, float(t)), steady=steady) for t in taus]
    # e_f(steps) = sum_j C Phi B d(j): choose each d(j) = sign of its coefficient
    row = loops[0].C_ef[0].copy()
    peak = 0.0
    for loop in reversed(loops):  # row = C A(k-1) ... A(j+1); coefficient of d(j) is row @ B
        peak += abs(float(row @ loop.B[:, 0]))
        row = row @ loop.A
    return peak


def test_the_bound_holds_against_constant_delays_and_worst_case_time_varying_runs(fast):
    plant, result = fast
    bound = fault_threshold(plant, result.gains, 1.0)
    frozen = max(_impulse_l1(plant, result.gains, float(t)) for t in tau_grid(plant, 21))
    assert bound.frozen_l1 == pytest.approx(frozen, rel=1e-3, abs=1e-9) or bound.frozen_l1 >= frozen
    assert bound.threshold >= frozen
    rng = np.random.default_rng(5)
    assert max(_worst_case_peak(plant, result.gains, rng) for _ in range(40)) <= bound.threshold
    assert bound.threshold <= 3.0 * frozen  # not loose: the 3x


@pytest.mark.parametrize("method, objective", [("certified", "hinf"), ("robust-separate", None)])
def test_not_loose_for_other_designs_either(method, objective):
    plant, result = designed("paper-continuous", method, objective)
    bound = fault_threshold(plant, result.gains, 0.5)
    assert bound.threshold == pytest.approx(0.5 * bound.per_unit_disturbance)
    assert 1.0 <= bound.ratio_to_frozen <= 3.0


def test_an_unstable_loop_has_no_threshold():
    plant, result = designed("paper-continuous", "separate")
    with pytest.raises(UserError, match="no threshold"):
        fault_threshold(plant, result.gains, 0.1)


def fm(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor", *args], capture_output=True, text=True, timeout=120)


def test_cli_json_and_errors(tmp_path, fast):
    from monitor.gains import write_gains

    plant, result = fast
    gains = tmp_path / "g.toml"
    write_gains(gains, result, plant)
    proc = fm("threshold", "--plant", "paper-continuous", "--gains", str(gains), "--disturbance-bound", "0.2", "--json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["threshold"] == pytest.approx(0.2 * doc["per_unit_disturbance"]) and doc["ratio_to_frozen"] >= 1.0
    bad = fm("threshold", "--plant", "paper-continuous", "--gains", str(gains), "--disturbance-bound", "nan")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    auto = fm("analyse", str(tmp_path / "missing.tlog"), "--plant", "paper-continuous", "--gains", str(gains),
              "--alarm-threshold", "auto")
    assert auto.returncode == 2 and "no such log file" in auto.stderr


def test_alarm_threshold_auto_is_the_bound_with_its_margin(fast):
    import argparse
    from types import SimpleNamespace

    from monitor.commands.run import AUTO_MARGIN, alarm_from_args
    from monitor.service.vehicles import Fleet

    plant, result = fast
    fleet = Fleet(SimpleNamespace(plant=plant, gains=SimpleNamespace(gains=result.gains)))

    def alarm(threshold, disturbance):
        return alarm_from_args(argparse.Namespace(alarm_threshold=threshold, disturbance_bound=disturbance,
                                                  alarm_clear=None, alarm_samples=2), fleet)

    config = alarm("auto", 0.1)
    assert config.threshold == pytest.approx(AUTO_MARGIN * fault_threshold(plant, result.gains, 0.1).threshold)
    assert config.clear == pytest.approx(0.5 * config.threshold)
    with pytest.raises(UserError, match="needs --disturbance-bound"):
        alarm("auto", None)
    with pytest.raises(UserError, match="auto only"):
        alarm(1.0, 0.1)
