"""The reported fault channel of chosen bandwidth: a low-pass outside the loop, and the bound it keeps."""

from __future__ import annotations

import math

import numpy as np

from monitor.design import default_fault_time_constant, reported_error_bound
from monitor.model.closed_loop import closed_loop
from monitor.model.delay_model import b0_of_tau
from monitor.model.estimator import Estimator
from monitor.model.norms import hinf_norm
from monitor.model.plant import load_plant, parse_plant
from tests.designs import designed


def test_the_reported_estimate_is_the_raw_one_low_passed_and_the_commands_do_not_change():
    plant, result = designed("paper-continuous", "certified")
    raw, filtered = Estimator(plant, result.gains), Estimator(plant, result.gains, fault_time_constant=2.0)
    s_raw, s_filtered = raw.initial_state(), filtered.initial_state()
    rng = np.random.default_rng(3)
    a, reported = math.exp(-plant.h / 2.0), 0.0
    for k in range(60):
        y = rng.normal(size=plant.l) + (1.0 if k > 20 else 0.0)
        one, two = raw.step(s_raw, k, y), filtered.step(s_filtered, k, y)
        assert np.allclose(one.u, two.u) and np.allclose(one.x_hat, two.x_hat)  # the loop is untouched
        reported = a * reported + (1 - a) * float(one.f_hat[0])
        assert math.isclose(float(two.f_hat[0]), reported, rel_tol=1e-12, abs_tol=1e-12)


def test_the_reported_error_bound_holds_for_the_cascade_at_every_delay():
    """``gamma_e + a / (1 - a)`` against the H-infinity norm of the loop followed by the filter, computed directly."""
    plant, result = designed("paper-continuous", "certified")
    T = 3.0
    a = math.exp(-plant.h / T)
    bound = reported_error_bound(result.gamma_e, plant.h, T)
    assert math.isclose(bound, result.gamma_e + a / (1 - a))
    for tau in np.linspace(plant.tau_min, plant.tau_max, 5):
        loop = closed_loop(plant, result.gains, b0_of_tau(plant, float(tau)))
        N, p = loop.A.shape[0], plant.p
        # z(k) = f(k) - f_rep(k-1): z+ = a z + (1-a) e_f + Delta f; the reported error is a z + (1-a) e_f
        A = np.block([[loop.A, np.zeros((N, 1))], [(1 - a) * loop.C_ef, np.full((1, 1), a)]])
        B = np.vstack([loop.B, np.hstack([np.zeros((1, p)), np.ones((1, 1))])])
        C = np.hstack([(1 - a) * loop.C_ef, np.full((1, 1), a)])
        norm = hinf_norm(A, B, C)
        assert norm <= bound * (1 + 1e-9), (tau, norm, bound)
        assert norm >= a / (1 - a) - result.gamma_e  # the filter's lag is most of it: the bound is not loose by much


def test_the_filter_is_on_by_default_only_for_a_plant_flying_in_turbulence():
    assert default_fault_time_constant(load_plant("paper-continuous")) is None
    base = (
        'form = "continuous"\nh = 0.05\ntau_min = 0.0\ntau_max = 0.02\nA_c = [[-1.0]]\nB_c = [[1.0]]\n'
        "D_cf = [[1.0]]\nD_cd = [[1.0]]\nC = [[1.0]]\n"
    )
    assert default_fault_time_constant(parse_plant(base + "[disturbance]\nsigma = 0.2\ntime_constant = 0.1\n")) is None
    light = parse_plant(base + '[disturbance]\nsigma = 0.4\ntime_constant = 0.4\nturbulence = "light"\n')
    assert default_fault_time_constant(light) == 1.0
    assert default_fault_time_constant(light, "none") is None  # design --turbulence none: calm air after all
    assert default_fault_time_constant(load_plant("paper-continuous"), "moderate") == 1.0
