"""A plant's ``[known_inputs]`` (monitor.model.known_inputs): the parser's one-line errors, the estimator's
prediction (``Gamma @ terms`` added, nothing else), and the live loop computing the terms from a sample's roll."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.gains import write_gains
from monitor.link.dialect import layout_by_name
from monitor.model.closed_loop import Gains
from monitor.model.estimator import Estimator
from monitor.model.known_inputs import bank_gravity, euler_pitch_rate
from monitor.model.plant import Plant, parse_plant
from monitor.service.alarm import DEFAULT_ALARM
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.vehicles import VehicleTable

DATA = Path(__file__).parent / "data"
BASE = (DATA / "c172p-longitudinal-turbulence.toml").read_text()
ELEVATOR = 'elevator = { field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }\n'
ROLL_R = (
    'roll = { field = "ATTITUDE.roll", scale = 57.29577951308232, unit = "deg" }\n'
    'r = { field = "ATTITUDE.yawspeed", scale = 57.29577951308232, unit = "deg/s" }\n'
)
TERMS = '\n[known_inputs]\nterms = ["bank_gravity", "euler_pitch_rate"]\n'
DEG = 57.29577951308232
H_US = 50_000
ATT, AOA, ACT, HUD = (layout_by_name(n) for n in ("ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS", "VFR_HUD"))
GAINS = Gains(
    L=0.4 * np.eye(4),
    M=np.array([[0.05, -0.01, 0.02, 0.0]]),
    K1=np.zeros((1, 4)),
    K2=np.zeros((1, 1)),
    K3=np.zeros((1, 1)),
)


def plant_text(roll: bool = True, terms: str = TERMS) -> str:
    return (BASE.replace(ELEVATOR, ELEVATOR + ROLL_R) if roll else BASE) + terms


def one_line_error(text: str) -> str:
    with pytest.raises(UserError) as err:
        parse_plant(text, "p.toml")
    assert "\n" not in str(err.value)
    return str(err.value)


# --- the parser ------------------------------------------------------------------------------------------------------


def test_the_parser_refuses_in_one_line_naming_the_key() -> None:
    bad = plant_text(terms='\n[known_inputs]\nterms = ["bank_gravity", "lift_curve"]\n')
    assert "key 'known_inputs.terms' names 'lift_curve', not a known term" in one_line_error(bad)
    dup = plant_text(terms='\n[known_inputs]\nterms = ["bank_gravity", "bank_gravity"]\n')
    assert "'bank_gravity' twice" in one_line_error(dup)
    assert "known_inputs.terms" in one_line_error(plant_text(terms="\n[known_inputs]\nterms = []\n"))
    assert "known_inputs.expr" in one_line_error(plant_text(terms='\n[known_inputs]\nexpr = "q"\n'))
    no_roll = one_line_error(plant_text(roll=False))
    assert "known_inputs.terms" in no_roll and "'roll' in [signals.measured]" in no_roll
    no_r = plant_text().replace(ROLL_R, ROLL_R.splitlines(keepends=True)[0])
    assert "'euler_pitch_rate' needs 'r'" in one_line_error(no_r)
    renamed = plant_text().replace('"theta", "airspeed"]', '"th", "airspeed"]').replace("theta = ", "th = ")
    assert "needs state 'theta' among the outputs" in one_line_error(renamed)
    rad = plant_text().replace('scale = 57.29577951308232, unit = "deg" }\nr', 'unit = "rad" }\nr')
    assert "'roll' in deg, its signal is in rad" in one_line_error(rad)
    discrete = (
        'form = "discrete"\nh = 0.05\ntau_min = 0.0\ntau_max = 0.01\nA = [[0.9]]\nB0 = [[0.1]]\nB1 = [[0.0]]\n'
        'C = [[1.0]]\nDf = [[0.1]]\nDd = [[0.0]]\n[known_inputs]\nterms = ["bank_gravity"]\n'
    )
    assert "known_inputs.terms' needs a continuous plant" in one_line_error(discrete)


def test_the_table_is_stored_and_leaves_the_digest_alone() -> None:
    with_terms, without = parse_plant(plant_text()), parse_plant(plant_text(terms=""))
    assert without.known_inputs is None and with_terms.known_inputs is not None
    assert with_terms.known_inputs.terms == ("bank_gravity", "euler_pitch_rate")
    assert with_terms.known_inputs.signals == ("roll", "r")
    assert with_terms.digest == without.digest == parse_plant(BASE).digest  # the gains stay valid


# --- the estimator ---------------------------------------------------------------------------------------------------


def _gamma(plant: Plant) -> np.ndarray:
    """int_0^h e^{A_c s} ds by its series, independently of monitor.model.discretize."""
    assert plant.continuous is not None
    A, h = plant.continuous.A_c, plant.h
    total, term = np.zeros_like(A), np.eye(len(A)) * h  # A^k h^{k+1} / (k+1)!
    for k in range(1, 40):
        total += term
        term = term @ A * h / (k + 1)
    return total


def _run(est: Estimator, known, mode: str, samples: int = 60) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    state, out = est.initial_state(), []
    for k in range(samples):
        if k in (20, 21):
            continue  # lost samples: predicted without the terms
        y, u = rng.normal(size=4), rng.normal(size=1)
        kn = known(k) if known is not None else None
        if mode == "observe":
            r = est.observe(state, k, y, u, known=kn)
        elif mode == "step":
            r = est.step(state, k, y, u_prev=u, known=kn)
        else:
            r, _ = est.compensate(state, k, y, u, [0.0], known=kn)
        out += [r.f_hat, r.x_hat, state.z.copy()]
    return out


@pytest.mark.parametrize("mode", ["observe", "step", "compensate"])
def test_known_zero_is_exactly_the_estimator_without_known_inputs(mode: str) -> None:
    with_terms, without = parse_plant(plant_text()), parse_plant(BASE)
    a = _run(Estimator(with_terms, GAINS), lambda k: [0.0] * 4, mode)
    b = _run(Estimator(without, GAINS), None, mode)
    c = _run(Estimator(without, GAINS), lambda k: [1.0, 2.0, 3.0, 4.0], mode)  # a plant without: ignored
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert all(np.array_equal(x, y) for x, y in zip(c, b, strict=True))


def test_a_steady_bank_moves_the_prediction_by_gamma_times_the_terms() -> None:
    plant = parse_plant(plant_text())
    values = {"alpha": 2.0, "q": 3.0, "theta": 4.0, "airspeed": 50.0, "roll": 30.0, "r": 6.0}
    assert plant.known_inputs is not None
    terms = plant.known_inputs.vector(values)
    phi, theta = math.radians(30.0), math.radians(4.0)
    expected_terms = [math.degrees(9.81 / 50.0 * math.cos(theta) * (math.cos(phi) - 1.0)), 0.0, 0.0, 0.0]
    expected_terms[2] = 3.0 * (math.cos(phi) - 1.0) - 6.0 * math.sin(phi)
    assert terms is not None and np.allclose(terms, expected_terms, rtol=1e-14, atol=0)
    assert terms[0] == bank_gravity(values) and terms[2] == euler_pitch_rate(values)
    est = Estimator(plant, GAINS)
    y, u = [0.3, -0.2, 0.1, 0.5], [0.4]
    for k in range(5):  # a steady bank, sample after sample
        s1, s2 = est.initial_state(), est.initial_state()
        s1.z = s2.z = np.linspace(-1.0, 1.0, len(s1.z))
        s1.z, s2.z = s1.z.copy(), s2.z.copy()
        est.observe(s1, k, y, u, known=terms)
        est.observe(s2, k, y, u)
        moved = s1.z - s2.z
        assert np.allclose(moved[:4], _gamma(plant) @ np.array(expected_terms), rtol=1e-10, atol=1e-14)
        assert np.all(moved[4:] == 0.0)  # f_hat and u(k-1) are not moved
    assert plant.known_inputs.vector({**values, "roll": math.nan}) is None
    assert plant.known_inputs.vector({k: v for k, v in values.items() if k != "r"}) is None


# --- the live loop ---------------------------------------------------------------------------------------------------


def _files(directory: Path, text: str, name: str) -> tuple[Path, Path]:
    plant_path, gains_path = directory / f"{name}.toml", directory / f"{name}-gains.toml"
    plant_path.write_text(text)
    result = DesignResult(
        "certified", GAINS, gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0
    )
    write_gains(gains_path, result, parse_plant(text, str(plant_path)))
    return plant_path, gains_path


def _fly(directory: Path, text: str, name: str, roll_deg: float = 30.0) -> list[float]:
    table = VehicleTable(Fleet(load_model(*_files(directory, text, name))), DEFAULT_ALARM, observe=True)
    f_hats = []
    for k in range(40):
        t = k * H_US
        alpha, q, theta, V, elevator = 0.5, 0.1 + 0.01 * k, 0.4, 51.0, 4.3
        msgs = [
            ("VFR_HUD", HUD.decode(HUD.unpacker.pack(V, V, 100.0, 0.0, 90, 60))),
            ("ATTITUDE", ATT.decode(ATT.unpacker.pack(t // 1000, roll_deg / DEG, theta / DEG, 0.0, 0.0, q / DEG, 0.1))),
            ("AOA_SSA", AOA.decode(AOA.unpacker.pack(t, alpha, 0.0))),
            ("ACTUATOR_OUTPUT_STATUS", ACT.decode(ACT.unpacker.pack(t, 1, elevator, *[0.0] * 31))),
        ]
        for msg, values in msgs:
            for vehicle, sample in table.message(1, msg, values, "r", k * 0.05):
                p = table.process(vehicle, sample, k * 0.05, k * 0.05)
                assert p is not None
                if text.endswith(TERMS):
                    assert "roll" in sample.values and "r" in sample.values
                f_hats.append(float(p.result.f_hat[0]))
    assert len(f_hats) >= 35
    return f_hats


def test_the_live_loop_adds_the_terms_from_the_samples_roll(tmp_path: Path) -> None:
    with_terms = _fly(tmp_path, plant_text(), "with")
    without = _fly(tmp_path, plant_text(terms=""), "without")
    plain = _fly(tmp_path, BASE, "plain")
    assert with_terms != without  # the turn's terms reach f_hat
    assert without == plain  # roll and r recorded, no [known_inputs]: unchanged
    assert _fly(tmp_path, plant_text(), "level", roll_deg=0.0) != with_terms


def test_run_refuses_a_signal_map_without_the_terms_signals(tmp_path: Path) -> None:
    plant_path, gains_path = _files(tmp_path, plant_text(), "p")
    signals = tmp_path / "signals.toml"
    section = BASE[BASE.index("\n[signals]") : BASE.index("[identification]")]
    signals.write_text(section)
    with pytest.raises(UserError, match="has no 'roll', which plant .* \\[known_inputs\\]"):
        load_model(plant_path, gains_path, signals_file=signals)
