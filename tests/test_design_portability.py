"""Designs that hold on another machine: every method on both presets, in any order, on data perturbed at 1e-9.

Why: another CPU rounds differently, and an interior-point solver's status word moves with the last digits
of the data (a preset that solves "optimal" here was "optimal_inaccurate" on a user's machine). Perturbing
every matrix entry at 1e-9 relative and changing the order of the solves in one process stands in for that
machine; every design must still succeed, and each must carry a point that the numpy re-check accepted.
"""

from __future__ import annotations

import tomllib
import warnings
from importlib import resources
from pathlib import Path

import cvxpy as cp
import numpy as np
import pytest

from monitor.checks.verify import verify_gains
from monitor.demo.methods import METHODS
from monitor.design import run_design
from monitor.design.separate import observer_alone
from monitor.design.solve import CHECK_MARGIN, PATHS, SolveFailed, solve_checked
from monitor.errors import DesignFailed
from monitor.model.plant import Plant, load_plant, parse_plant, plant_from_table
from tests.designs import designed

PRESETS = ("paper", "paper-continuous")
INACCURATE = Path(__file__).parent / "data" / "paper-continuous-inaccurate.toml"


def perturbed(preset: str, seed: int, relative: float = 1e-9) -> Plant:
    """The preset with every non-zero matrix entry multiplied by ``1 + relative * N(0, 1)``."""
    raw = tomllib.loads(resources.files("monitor.presets").joinpath(f"{preset}.toml").read_text("utf-8"))
    rng = np.random.default_rng(seed)

    def shake(value):
        if isinstance(value, list):
            return [shake(v) for v in value]
        return value * (1.0 + relative * rng.standard_normal()) if isinstance(value, float) and value else value

    for key in ("A_c", "B_c", "D_cf", "D_cd", "A", "B0", "B1", "C", "Df", "Dd", "E"):
        if key in raw:
            raw[key] = shake(raw[key])
    return plant_from_table(raw, f"{preset} perturbed (seed {seed})")


def _design_all(plants: list[Plant], methods: tuple[str, ...]) -> list[tuple[str, str, object]]:
    """Every method on every plant in the given order, in this one process; (plant, method, result or error)."""
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for plant in plants:
            for method in methods:
                try:
                    out.append((plant.source, method, run_design(method, plant)))
                except DesignFailed as exc:
                    out.append((plant.source, method, exc))
    return out


def _assert_all_designed(results: list[tuple[str, str, object]]) -> None:
    failed = [f"{source} / {method}: {r}" for source, method, r in results if isinstance(r, Exception)]
    assert not failed, "designs failed:\n" + "\n".join(failed)
    for source, method, r in results:
        assert r.solved is not None and r.solved.margin >= CHECK_MARGIN, (source, method)
        assert r.solved.path in {p.name for p in PATHS}
        for name in ("L", "M", "K1", "K2", "K3"):
            assert np.all(np.isfinite(getattr(r.gains, name))), (source, method, name)


def test_every_demo_design_on_both_presets_in_the_demo_order():
    _assert_all_designed(_design_all([load_plant(p) for p in PRESETS], METHODS))


def test_every_demo_design_on_presets_perturbed_at_1e_9_in_reverse_order():
    """Another machine's rounding (1e-9) and another order of solves in one process, at once."""
    plants = [perturbed(p, seed=1) for p in reversed(PRESETS)]
    results = _design_all(plants, tuple(reversed(METHODS)))
    _assert_all_designed(results)
    # the certified (default) design stays what verify calls certified on the perturbed plants too
    for plant in plants:
        result = next(r for source, method, r in results if source == plant.source and method == "certified")
        v = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
        assert v.stable and v.certificate_valid is True
    # and it is the same design as on the exact preset, to the solver's accuracy: the data moved by 1e-9
    for plant, preset in zip(plants, reversed(PRESETS), strict=True):
        perturbed_K1 = next(r for s, m, r in results if s == plant.source and m == "certified").gains.K1
        exact_K1 = designed(preset, "certified")[1].gains.K1  # the session's design of the exact preset
        assert np.allclose(perturbed_K1, exact_K1, rtol=1e-4, atol=1e-6), preset


def test_hinf_objective_on_a_perturbed_preset():
    """One preset, and the H-infinity search stopped at its first certified candidate (``time_budget_s=0``): the
    joint LMI posed, solved, re-checked in numpy and certified on perturbed data, which is what could fail on
    another machine; the search for the smallest gamma_e runs in full, unperturbed, in test_design."""
    plant = perturbed("paper-continuous", 3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_design("certified", plant, objective="hinf", time_budget_s=0.0)
    assert "stopped at its 0-s budget" in result.notes[-1]  # the first certified candidate, as asked
    assert result.solved is not None and result.solved.margin >= CHECK_MARGIN
    v = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    assert v.stable and v.certificate_valid is True


def test_the_plant_a_user_machine_called_inaccurate_still_designs():
    """A 1e-9 perturbation of paper-continuous on which Clarabel reports optimal_inaccurate (found here)."""
    plant = parse_plant(INACCURATE.read_text("utf-8"), str(INACCURATE))
    _assert_all_designed(_design_all([plant], ("robust-separate", "separate")))


def _tiny_lmi() -> tuple[cp.Problem, cp.Variable]:
    """min t s.t. [[t, 1], [1, 1]] >= 0: optimum t = 1."""
    t = cp.Variable()
    return cp.Problem(cp.Minimize(t), [cp.bmat([[t, 1.0], [1.0, 1.0]]) >> 0]), t


def test_a_point_is_accepted_by_its_check_not_by_the_status_word():
    problem, t = _tiny_lmi()
    solved = solve_checked(problem, lambda: 1.0)
    assert solved.path == PATHS[0].name and solved.margin == 1.0
    assert abs(t.value - 1.0) < 1e-6


def test_an_optimal_point_whose_check_fails_is_refused_on_every_path():
    problem, _ = _tiny_lmi()
    with pytest.raises(SolveFailed) as err:
        solve_checked(problem, lambda: -1.0)
    message = str(err.value)
    for path in PATHS:
        assert f"{path.name}: " in message
    assert "check failed" in message


def test_a_check_that_cannot_be_evaluated_proves_nothing():
    problem, _ = _tiny_lmi()

    def singular() -> float:
        return float(np.linalg.solve(np.zeros((2, 2)), np.ones(2))[0])

    with pytest.raises(SolveFailed):
        solve_checked(problem, singular, paths=PATHS[:1])


def test_an_infeasible_observer_names_the_method_that_failed():
    """An unstable mode the output never sees: no observer exists, and the message says whose LMI it was."""
    plant = parse_plant(
        'form = "discrete"\nh = 1.0\ntau_min = 0.0\ntau_max = 0.4\nA = [[1.5, 0.0], [0.0, 0.5]]\n'
        "B0 = [[1.0], [1.0]]\nB1 = [[0.1], [0.1]]\nC = [[0.0, 1.0]]\nDf = [[1.0], [1.0]]\n"
        "Dd = [[1.0], [1.0]]\n"
    )
    with pytest.raises(DesignFailed, match=r"^robust-separate method, observer LMI: clarabel: "):
        observer_alone(plant, [np.zeros((2, 1))], method="robust-separate")


def test_importing_the_design_package_does_not_load_cvxpy():
    """The CLI imports ``monitor.design`` for its method names: a second of cvxpy there delays every command."""
    import subprocess
    import sys

    code = "import sys, monitor.design, monitor.design.result; print('cvxpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr
