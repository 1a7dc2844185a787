"""Design -> independent verify round trips for every method on both presets (real Clarabel solves)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from monitor.checks.verify import verify_gains
from monitor.design import run_design
from monitor.design.paper import lemma3_K2_K3
from monitor.errors import DesignFailed
from monitor.model.closed_loop import Gains, closed_loop, observer_indices
from monitor.model.plant import load_plant, parse_plant
from tests.designs import designed


@pytest.mark.parametrize(
    "preset, objective, gamma_max, rho_bound",
    [
        ("paper", "fast", 2.4, 0.85),
        ("paper-continuous", "fast", 2.4, 0.85),
        ("paper-continuous", "hinf", 2.0, 0.8),  # ~3 s a design: one preset is enough (the benchmark runs both)
    ],
)
def test_certified_design_is_certified_stable_and_meets_its_bound(preset, objective, gamma_max, rho_bound):
    plant, result = designed(preset, "certified", objective)
    assert result.objective == objective
    assert result.gamma_e <= gamma_max  # hinf: the H-infinity target; fast: the bound for the fast design
    assert result.gamma_e >= 1.6  # the floor is about 1.618
    v = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    assert v.stable and v.rho_max < rho_bound and v.rho_time_varying < 1
    assert v.certificate_valid is True
    assert v.hinf_ef <= result.gamma_e * (1 + 1e-6) and v.hinf_y <= result.gamma_z * (1 + 1e-6)
    assert v.hinf_ef >= 1.6  # no design beats the floor of Delta f -> e_f
    assert v.fault_leak < 1e-9


@pytest.mark.parametrize("preset", ["paper", "paper-continuous"])
def test_fast_design_estimates_a_step_fault_two_samples_after_onset_at_the_nominal_delay(preset):
    """Observer (5) cannot beat two samples; the fast design reaches it exactly when tau is nominal."""
    plant, result = designed(preset, "certified", "fast")
    loop = closed_loop(plant, result.gains, plant.B0)
    xi = loop.B[:, plant.p]  # onset of a unit step fault
    e_f = []
    for _ in range(6):
        e_f.append(float((loop.C_ef @ xi)[0]))
        xi = loop.A @ xi
    assert e_f[0] == pytest.approx(1.0) and e_f[1] == pytest.approx(1.0)
    assert max(abs(e) for e in e_f[2:]) < 1e-9


def test_fast_design_settles_faster_than_hinf_when_the_delay_varies():
    """Simulated paper scenario (20 delay seeds, the monitor's own Monte-Carlo): fast beats hinf on settling."""
    from monitor.demo.montecarlo import monte_carlo

    plant, fast = designed("paper-continuous", "certified", "fast")
    _, hinf = designed("paper-continuous", "certified", "hinf")

    def settling(gains) -> list[int]:
        scores = monte_carlo(plant, gains, 20, 100, "bias:2@20", "uniform:0:0.46", "paper")
        return [s.settling_steps if s.settling_steps is not None else 100 for s in scores]

    fast_s, hinf_s = settling(fast.gains), settling(hinf.gains)
    assert fast_s[0] <= 3 and np.mean(fast_s) <= 4.8 and max(fast_s) <= 7  # the targets
    assert np.mean(fast_s) < np.mean(hinf_s)


def test_a_tampered_certificate_is_rejected():
    plant, result = designed("paper", "certified")
    cert = dict(result.certificate)
    cert["P"] = cert["P"] * np.diag([1, 1, 1, 1, 1, 50.0])
    v = verify_gains(plant, result.gains, cert, result.gamma_e, result.gamma_z)
    assert v.certificate_valid is False


def test_paper_method_works_on_the_continuous_plant():
    plant, result = designed("paper-continuous", "paper")
    assert verify_gains(plant, result.gains).stable


def test_paper_method_cannot_pass_on_the_printed_example_and_why():
    """Lemma 3's K2 = -B0^+ B1 admits no stabilising K1 at all for the printed matrices.

    The controller block [x; u(k-1)] of the real loop at the nominal delay, with K2 fixed by Lemma 3,
    has a spectral radius >= 1 for every K1 on a wide grid: the design cannot be rescued by any K1.
    """
    plant, result = designed("paper", "paper")
    assert not verify_gains(plant, result.gains).stable
    K2, K3 = lemma3_K2_K3(plant)
    sx, _, _, su = observer_indices(plant)
    idx = list(range(sx.start, sx.stop)) + list(range(su.start, su.stop))
    for k1 in np.linspace(-50, 50, 2001):
        g = Gains(L=result.gains.L, M=result.gains.M, K1=np.array([[k1]]), K2=K2, K3=K3)
        A = closed_loop(plant, g, plant.B0, steady=(np.zeros((2, 1)), np.zeros((1, 1)))).A
        assert np.max(np.abs(np.linalg.eigvals(A[np.ix_(idx, idx)]))) >= 1.0


@pytest.mark.parametrize("preset", ["paper", "paper-continuous"])
def test_separate_design_is_stable_only_at_the_nominal_delay(preset):
    """The baseline's observer and controller are each optimal at tau_bar, but the delay couples them."""
    plant, result = designed(preset, "separate")
    nominal = closed_loop(plant, result.gains, plant.B0)
    assert np.max(np.abs(np.linalg.eigvals(nominal.A))) < 1.0
    assert result.gamma_e < 1.7  # the observer alone is near the 1.618 floor...
    assert not verify_gains(plant, result.gains).stable  # ...but the real loop over the interval is not stable


def test_infeasible_design_fails_cleanly():
    # C = 0: neither the state nor the fault is observable, so no observer exists.
    text = (
        'form="discrete"\nh=1.0\ntau_min=0.0\ntau_max=0.3\nA=[[0.5, 0.1], [0.0, 0.4]]\nB0=[[0.2], [0.3]]\n'
        "B1=[[0.1], [0.1]]\nC=[[0.0, 0.0]]\nDf=[[0.2], [0.2]]\nDd=[[0.0], [0.2]]\nE=[[0.0], [1.0]]\n"
    )
    plant = parse_plant(text, source="unobservable.toml")
    for method in ("certified", "paper"):
        with pytest.raises(DesignFailed):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                run_design(method, plant, **({"max_evaluations": 6} if method == "certified" else {}))


@pytest.mark.parametrize("preset", ["paper", "paper-continuous"])
def test_robust_separate_design_is_a_stable_baseline(preset):
    """Each part designed alone but robust over the delay polytope: the real loop is stable (verify says so),
    unlike the nominal separate design, and its parts' bounds are not claimed for the real loop."""
    plant, result = designed(preset, "robust-separate")
    v = verify_gains(plant, result.gains)
    assert v.stable and v.rho_max < 0.95 and v.rho_time_varying < 0.9
    assert "not the real loop" in result.bounds_apply_to
    _, nominal = designed(preset, "separate")
    assert not verify_gains(plant, nominal.gains).stable


WIDE_INTERVAL_PLANT = """
form = "continuous"
name = "unstable-pitch-wide"
h = 1.0
tau_min = 0.0
tau_max = 0.6
A_c = [[0.6, 1.0], [0.0, -3.0]]
B_c = [[0.0], [2.0]]
D_cf = [[0.0], [1.0]]
D_cd = [[0.5], [1.0]]
C = [[1.0, 0.0]]
"""


def test_the_default_falls_back_to_hinf_where_fast_finds_no_certificate(tmp_path):
    """An unstable plant over [0, 0.6 h]: the fast objective fails, the default design is still certified."""
    plant = parse_plant(WIDE_INTERVAL_PLANT, "wide")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_design("certified", plant)
    assert result.objective == "hinf" and "fell back to the H-infinity objective" in result.notes[0]
    assert "the fast objective failed (fast design: no common Lyapunov certificate" in result.notes[0]
    v = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    assert v.stable and v.certificate_valid is True


def test_the_fallback_stops_at_its_budget_with_a_certified_candidate(monkeypatch):
    """With its budget spent the H-infinity fallback keeps the first certified candidate: quick, still certified."""
    import monitor.design as design
    import monitor.design.fast as fast

    def no_certificate(plant, **options):
        raise DesignFailed("fast design: no common Lyapunov certificate (as on a plant where it fails)")

    monkeypatch.setattr(fast, "design_fast", no_certificate)
    monkeypatch.setattr(design, "FALLBACK_BUDGET_S", 0.0)
    plant = load_plant("paper-continuous")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_design("certified", plant)
    assert result.objective == "hinf" and "stopped at its 0-s budget" in result.notes[-1]
    assert "1 controller candidates evaluated" in result.notes[-1]
    v = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    assert v.stable and v.certificate_valid is True
