"""`fault-monitor threshold`: a proven bound on |f_hat| without a fault, checked against what the loop can reach."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from monitor.checks.threshold import fault_threshold
from monitor.errors import UserError
from monitor.model.closed_loop import closed_loop, steady_state
from monitor.model.delay_model import b0_of_tau, tau_grid
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


def _worst_case_peak(plant, gains, rng, steps: int = 80, ends: bool = False) -> float:
    """|f_hat| at the end of a run whose d(k) takes the sign that maximises it, delays random (time-varying),
    anywhere in the interval or (``ends``) switching between its two ends."""
    steady = steady_state(plant, gains)
    taus = (
        rng.choice([plant.tau_min, plant.tau_max], steps) if ends else rng.uniform(plant.tau_min, plant.tau_max, steps)
    )
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
    assert max(_worst_case_peak(plant, result.gains, rng, ends=bool(i % 2)) for i in range(40)) <= bound.threshold
    assert bound.threshold <= 3.0 * frozen  # not loose: the 3x


@pytest.mark.parametrize("method, objective", [("certified", "hinf"), ("robust-separate", None)])
def test_not_loose_for_other_designs_either(method, objective):
    plant, result = designed("paper-continuous", method, objective)
    bound = fault_threshold(plant, result.gains, 0.5)
    assert bound.threshold == pytest.approx(0.5 * bound.per_unit_disturbance)
    assert 1.0 <= bound.ratio_to_frozen <= 3.0


HAND = {  # gains written from numbers, as a user would: the paper's printed observer, a milder one, an unstable one
    "printed": "L = [[1.87], [1.63]]\nM = [[7.0]]\nK1 = [[-0.2]]\nK2 = [[0.7]]\nK3 = [[-0.1]]\n",
    "mild": "L = [[0.9], [0.6]]\nM = [[1.5]]\nK1 = [[-0.1]]\nK2 = [[0.5]]\nK3 = [[-0.05]]\n",
    "unstable": "L = [[0.0], [0.0]]\nM = [[-1.0]]\nK1 = [[0.0]]\nK2 = [[0.0]]\nK3 = [[0.0]]\n",
}


def _hand_gains(tmp_path, name: str):
    path = tmp_path / f"{name}.toml"
    path.write_text('[gains]\nmethod = "hand"\n' + HAND[name])
    return path


@pytest.mark.parametrize("preset, name", [("paper", "printed"), ("paper-continuous", "mild")])
def test_hand_written_gains_on_both_presets(tmp_path, preset, name):
    from monitor.gains import read_gains
    from monitor.model.plant import load_plant

    plant, gains = load_plant(preset), read_gains(_hand_gains(tmp_path, name)).gains
    bound = fault_threshold(plant, gains, 1.0)
    frozen = [_impulse_l1(plant, gains, float(t)) for t in tau_grid(plant, 11)]
    assert min(bound.threshold - f for f in frozen) >= 0 and bound.threshold <= 3.0 * max(frozen)
    rng = np.random.default_rng(7)
    assert max(_worst_case_peak(plant, gains, rng, ends=bool(i % 2)) for i in range(10)) <= bound.threshold
    assert bound.method in ("paths", "blocks") and bound.common_rate is not None and bound.common_rate < 1.0


def test_cli_refuses_unstable_gains_and_auto_without_a_bound(tmp_path):
    unstable = fm(
        "threshold",
        "--plant",
        "paper",
        "--gains",
        str(_hand_gains(tmp_path, "unstable")),
        "--disturbance-bound",
        "0.1",
        "--json",
    )
    assert unstable.returncode != 0 and unstable.stdout == ""
    assert len(unstable.stderr.strip().splitlines()) == 1 and "no threshold" in unstable.stderr
    auto = fm(
        "run",
        "--plant",
        "paper",
        "--gains",
        str(_hand_gains(tmp_path, "printed")),
        "--force",
        "--alarm-threshold",
        "auto",
    )
    errors = [line for line in auto.stderr.splitlines() if "error:" in line]  # --force adds a warning line
    assert auto.returncode == 2 and len(errors) == 1 and "needs --disturbance-bound" in errors[0]


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
    assert {"frozen_l1", "tau_frozen_worst", "method", "bound_paths", "bound_blocks", "ellipsoid"} <= set(doc)
    assert doc["per_unit_disturbance"] == pytest.approx(min(doc["bound_paths"], doc["bound_blocks"]), rel=1e-6)
    bad = fm("threshold", "--plant", "paper-continuous", "--gains", str(gains), "--disturbance-bound", "nan")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    auto = fm(
        "analyse",
        str(tmp_path / "missing.tlog"),
        "--plant",
        "paper-continuous",
        "--gains",
        str(gains),
        "--alarm-threshold",
        "auto",
    )
    assert auto.returncode == 2 and "no such log file" in auto.stderr


def test_alarm_threshold_auto_is_the_bound_with_its_margin(fast):
    import argparse
    from types import SimpleNamespace

    from monitor.commands.run import AUTO_MARGIN, alarm_from_args
    from monitor.service.fleet_file import Fleet

    plant, result = fast
    model = SimpleNamespace(plant=plant, gains=SimpleNamespace(gains=result.gains))
    model.point_models = lambda: (model,)  # a single-point model runs itself (VehicleModel.point_models)
    fleet = Fleet(model)

    def alarm(threshold, disturbance):
        return alarm_from_args(
            argparse.Namespace(
                alarm_threshold=threshold, disturbance_bound=disturbance, alarm_clear=None, alarm_samples=2
            ),
            fleet,
        )

    config = alarm("auto", 0.1)
    assert config.threshold == pytest.approx(AUTO_MARGIN * fault_threshold(plant, result.gains, 0.1).threshold)
    assert config.clear == pytest.approx(0.5 * config.threshold)
    with pytest.raises(UserError, match="needs --disturbance-bound"):
        alarm("auto", None)
    with pytest.raises(UserError, match="auto only"):
        alarm(1.0, 0.1)
