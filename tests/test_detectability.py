"""Detectability: the Gaussian figures against the vehicle's own simulation of the loop, the proven threshold
against random bounded air, the command in process, and ``run --alarm-threshold auto --turbulence``."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import UserError

SIGMA, TAU_D = 0.01, 3.0  # the Gauss-Markov air of the paper's plant here (plant units, seconds)


def _paper():
    from tests.designs import designed

    return designed("paper-continuous", "certified")


def _fly_linear(plant, gains, steps: int, delay: str, wind, fault: str | None = None, alarm=None, seed: int = 0):
    """The vehicle's exact simulation of the continuous plant, the monitor's estimator answering at once."""
    from monitor.jsbsim_flights import ClosedLoop
    from monitor.model.estimator import Estimator
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec
    from sim_vehicle.simulation import Simulation

    loop = ClosedLoop(Estimator(plant, gains), alarm=alarm)
    sim = Simulation(
        plant=plant,
        sink=loop,
        steps=steps,
        delay=parse_delay_spec(delay, seed=seed),
        wind=wind,
        fault=parse_fault_spec(fault),
        seed=seed,
    )
    return loop.fly(sim)


def test_fhat_std_correlation_and_crossings_match_a_long_simulation_of_the_loop():
    """Independent code: sim_vehicle integrates the continuous plant with its own Gauss-Markov gusts, the
    monitor's Estimator closes the loop; the Lyapunov std and Rice's rate come from closed_loop's matrices."""
    from monitor.checks.detectability import fhat_noise, upcrossing_rate
    from monitor.wire.specs import Wind

    plant, result = _paper()
    noise, _ = fhat_noise(plant, result.gains, SIGMA, TAU_D, per_hour=1.0)
    loop = _fly_linear(
        plant,
        result.gains,
        20_000,
        f"const:{noise.tau}",
        Wind(oscillator=False, sigma=SIGMA, tau=TAU_D, h=plant.h, seed=7),
    )
    f = np.array([loop.f_hat[k] for k in range(100, 20_000)])
    assert f.std() == pytest.approx(noise.std, rel=0.05), (f.std(), noise.std)
    rho = float(np.mean(f[:-1] * f[1:]) / np.mean(f * f))
    assert rho == pytest.approx(noise.rho, abs=0.03), (rho, noise.rho)
    for level in (1.0, 2.0):  # Rice's rate is at or above the sampled sequence's own (module docstring)
        c = level * noise.std
        seen = np.sum((f[:-1] < c) & (f[1:] >= c)) + np.sum((f[:-1] > -c) & (f[1:] <= -c))
        expected = 2 * upcrossing_rate(c, noise.std, noise.rho, plant.h) * plant.h * (len(f) - 1)
        assert 0.8 * expected <= seen <= 1.15 * expected, (level, seen, expected)


class _Bounded:
    """Random air within +-D: uniform, or bang-bang with random switching (the l1 bound's worst kind)."""

    def __init__(self, bound: float, seed: int, bang: bool) -> None:
        self.bound, self.seed, self.bang = bound, seed, bang

    def values(self):
        rng = np.random.default_rng(self.seed)
        sign = 1.0
        while True:
            if self.bang:
                sign = -sign if rng.random() < 0.3 else sign
                yield self.bound * sign
            else:
                yield float(rng.uniform(-self.bound, self.bound))


def test_the_proven_threshold_holds_and_the_bias_is_surely_detected_under_random_bounded_air_and_delays():
    from monitor.checks.detectability import detectability
    from monitor.service.alarm import AlarmConfig

    plant, result = _paper()
    D = 0.001
    r = detectability(plant, result.gains, disturbance_bound=D, within_s=5.0)
    assert r.mode == "bounded" and r.threshold == pytest.approx(1.25 * r.noise_bound) and math.isfinite(r.bias)
    onset, window = 150, int(r.within_s / plant.h)
    for seed in range(4):
        loop = _fly_linear(
            plant,
            result.gains,
            onset + window + 2,
            f"uniform:{plant.tau_min}:{plant.tau_max}",
            _Bounded(D, seed, bang=seed % 2 == 0),
            fault=f"bias:{r.bias!r}@{onset}",
            alarm=AlarmConfig(r.threshold, r.clear, r.alarm_samples),
            seed=seed,
        )
        before = max(abs(loop.f_hat[k]) for k in range(onset))
        assert before <= r.noise_bound, (seed, before, r.noise_bound)
        assert loop.raised(0, onset) == []
        raised = loop.raised(onset)
        assert raised and raised[0] - onset <= window, (seed, raised)


def test_turbulence_levels_scale_by_the_milspec_intensities_and_a_plant_without_air_is_refused():
    from dataclasses import replace

    from monitor.checks.detectability import detectability, gust_sigma_ft_s
    from monitor.model.plant import Disturbance

    assert gust_sigma_ft_s("moderate", 3000) / gust_sigma_ft_s("light", 3000) == pytest.approx(1.418, abs=1e-3)
    assert gust_sigma_ft_s("light", 500) == pytest.approx(2.5)  # 0.1 W20 below 1000 ft
    plant, result = _paper()
    with pytest.raises(UserError, match="identify it from a flight in turbulence, or give --disturbance-bound"):
        detectability(plant, result.gains, turbulence="light")
    aired = replace(plant, disturbance=Disturbance(sigma=SIGMA, time_constant=TAU_D, turbulence="light"))
    light = detectability(aired, result.gains, turbulence="light", within_s=5.0)
    severe = detectability(aired, result.gains, turbulence="severe", within_s=5.0)
    ratio = gust_sigma_ft_s("severe", 3000) / gust_sigma_ft_s("light", 3000)
    assert severe.threshold == pytest.approx(ratio * light.threshold, rel=1e-9)  # linear in sigma
    assert light.threshold < light.bias < 2 * light.threshold


@pytest.fixture()
def aired_files(tmp_path: Path) -> tuple[str, str]:
    """The paper's plant with a [disturbance] table, and its certified gains written for that file."""
    from importlib import resources

    from monitor.gains import write_gains
    from monitor.model.plant import load_plant

    _, result = _paper()
    text = resources.files("monitor.presets").joinpath("paper-continuous.toml").read_text("utf-8")
    plant_file = tmp_path / "aired.toml"
    plant_file.write_text(text + f'\n[disturbance]\nsigma = {SIGMA}\ntime_constant = {TAU_D}\nturbulence = "light"\n')
    gains_file = tmp_path / "gains.toml"
    write_gains(gains_file, result, load_plant(str(plant_file)))
    return str(plant_file), str(gains_file)


def test_the_command_reports_json_and_refuses_bad_input_in_one_line(aired_files, capsys):
    from monitor.cli import main

    plant, gains = aired_files
    assert (
        main(
            ["detectability", "--plant", plant, "--gains", gains, "--turbulence", "moderate", "--within", "5", "--json"]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["mode"] == "turbulence" and out["turbulence"] == "moderate" and out["threshold"] > 0
    assert out["bias"] > out["threshold"] and out["sigma_ratio"] == pytest.approx(1.418, abs=1e-3)
    for argv, message in [
        (["--turbulence", "light", "--disturbance-bound", "0.1"], "not allowed with argument"),
        (["--turbulence", "light", "--monte-carlo", "2"], "--monte-carlo needs --aircraft"),
        (["--disturbance-bound", "-1"], "--disturbance-bound must be a finite number >= 0"),
        (["--turbulence", "light", "--false-alarms-per-hour", "1e9"], "ask for fewer"),
    ]:
        assert _main(["detectability", "--plant", plant, "--gains", gains, *argv]) == 2
        err = capsys.readouterr().err
        assert message in err.strip().splitlines()[-1], err  # the last line says it (argparse prints usage above)


def _main(argv: list[str]) -> int:
    """The exit code, whether argparse exits (usage errors) or main returns (UserError: one line, 2)."""
    from monitor.cli import main

    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code)


def test_run_auto_threshold_takes_the_turbulence_level(aired_files):
    from monitor.checks.detectability import turbulence_threshold
    from monitor.commands.run import alarm_from_args
    from monitor.service.fleet_file import Fleet, load_model

    plant, gains = aired_files
    model = load_model(plant, gains)
    fleet = Fleet(model)
    args = argparse.Namespace(
        alarm_threshold="auto", disturbance_bound=None, turbulence="moderate", alarm_clear=None, alarm_samples=2
    )
    config = alarm_from_args(args, fleet)
    assert config.threshold == pytest.approx(turbulence_threshold(model.plant, model.gains.gains, "moderate"))
    with pytest.raises(UserError, match="not both"):
        alarm_from_args(argparse.Namespace(**{**vars(args), "disturbance_bound": 0.1}), fleet)
    with pytest.raises(UserError, match="--turbulence applies to --alarm-threshold auto only"):
        alarm_from_args(argparse.Namespace(**{**vars(args), "alarm_threshold": 1.0}), fleet)
