"""The closed-loop matrices against a direct simulation of plant + Estimator with time-varying delay."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.model.closed_loop import Gains, closed_loop, fault_cancelling_K3, steady_state
from monitor.model.delay_model import b0_of_tau, b0_polytope, input_sum, tau_grid
from monitor.model.estimator import Estimator
from monitor.model.plant import load_plant

GAINS = dict(L=np.array([[1.87], [1.63]]), M=np.array([[6.9]]), K1=np.array([[-0.23]]), K2=np.array([[0.76]]))


@pytest.mark.parametrize("preset", ["paper", "paper-continuous"])
def test_loop_matrices_reproduce_a_direct_simulation(preset):
    p = load_plant(preset)
    g = Gains(**GAINS, K3=fault_cancelling_K3(p, GAINS["K2"]))
    est = Estimator(p, g)
    state = est.initial_state()
    rng = np.random.default_rng(3)
    S_x, S_u = steady_state(p, g)
    x = np.zeros(p.n)
    u_prev = np.zeros(p.m)
    xi = np.zeros(2 * p.n + p.q + p.m)
    f = lambda k: np.array([2.0 if k >= 20 else 0.0]) + (0.05 * (k - 40) if k >= 40 else 0.0)  # noqa: E731
    for k in range(80):
        tau = rng.uniform(p.tau_min, p.tau_max)
        d = np.array([0.001 * np.cos(0.125 * k)])
        y = p.C @ x
        step = est.step(state, k, y)
        B0t = b0_of_tau(p, tau)
        B1t = input_sum(p) - B0t
        # the loop's state, rebuilt from the simulation, must match the matrices' prediction
        e_x, e_f = x - step.x_hat, f(k) - step.f_hat
        direct = np.concatenate([x - S_x @ f(k), e_x, e_f, u_prev - S_u @ f(k)])
        np.testing.assert_allclose(direct, xi, atol=1e-9)
        np.testing.assert_allclose(y, p.C @ xi[: p.n] + p.C @ S_x @ f(k), atol=1e-9)
        loop = closed_loop(p, g, B0t, steady=(S_x, S_u))
        xi = loop.A @ xi + loop.B @ np.concatenate([d, f(k + 1) - f(k)])
        x = p.A @ x + B0t @ step.u + B1t @ u_prev + p.Df @ f(k) + p.Dd @ d
        u_prev = step.u


def test_fault_cancelling_K3_leaves_no_steady_output():
    p = load_plant("paper-continuous")
    g = Gains(**GAINS, K3=fault_cancelling_K3(p, GAINS["K2"]))
    S_x, _ = steady_state(p, g)
    assert abs((p.C @ S_x).item()) < 1e-12


@pytest.mark.parametrize("preset", ["paper", "paper-continuous"])
def test_polytope_contains_the_whole_delay_curve(preset):
    from scipy.optimize import linprog

    p = load_plant(preset)
    V = np.array([v.ravel() for v in b0_polytope(p)])
    for t in tau_grid(p, 301):
        pt = b0_of_tau(p, float(t)).ravel()
        res = linprog(
            np.zeros(len(V)),
            A_eq=np.vstack([V.T, np.ones((1, len(V)))]),
            b_eq=np.append(pt, 1),
            bounds=[(0, None)] * len(V),
        )
        assert res.status == 0, f"B0({t}) outside the polytope"


def test_the_prism_holds_every_point_of_a_thin_cloud_with_2_dim_vertices():
    """The 4-state aircraft case: a nearly straight curve in R^4, blown up into cross-polytopes."""
    from scipy.optimize import linprog

    from monitor.model.delay_model import _oriented_prism

    rng = np.random.default_rng(4)
    for dim in (3, 4, 5):
        direction = rng.normal(size=dim)
        curve = np.array([t * direction + 1e-3 * t**2 * rng.normal(size=dim) for t in np.linspace(0, 1, 9)])
        cloud = np.array([pt + s * 1e-4 * e for pt in curve for e in np.eye(dim) for s in (1.0, -1.0)])
        V = _oriented_prism(cloud)
        assert len(V) <= 2 * dim
        for pt in cloud:
            res = linprog(
                np.zeros(len(V)),
                A_eq=np.vstack([V.T, np.ones((1, len(V)))]),
                b_eq=np.append(pt, 1),
                bounds=[(0, None)] * len(V),
            )
            assert res.status == 0, f"a cloud point outside the prism (dim {dim})"


def test_discrete_preset_curve_passes_through_printed_B0_at_nominal_delay():
    p = load_plant("paper")
    np.testing.assert_allclose(b0_of_tau(p, p.tau_bar), p.B0, atol=1e-12)


def test_estimator_refuses_stale_and_duplicate_samples_and_predicts_over_gaps():
    p = load_plant("paper-continuous")
    est = Estimator(p, Gains(**GAINS, K3=fault_cancelling_K3(p, GAINS["K2"])))
    s = est.initial_state()
    est.step(s, 5, np.array([0.1]))
    with pytest.raises(ValueError):
        est.step(s, 5, np.array([0.1]))
    with pytest.raises(ValueError):
        est.step(s, 4, np.array([0.1]))
    assert est.step(s, 8, np.array([0.1])).skipped == 2


def test_fused_estimator_step_equals_equations_5_and_6():
    p = load_plant("paper")
    g = Gains(**GAINS, K3=fault_cancelling_K3(p, GAINS["K2"]))
    est = Estimator(p, g)
    s = est.initial_state()
    x_hat, f_hat, u_prev = np.zeros(2), np.zeros(1), np.zeros(1)
    rng = np.random.default_rng(5)
    for k in range(30):
        y = rng.normal(size=1)
        r = y - p.C @ x_hat
        u = g.K1 @ y + g.K2 @ u_prev + g.K3 @ f_hat
        step = est.step(s, k, y)
        np.testing.assert_allclose(step.u, u, atol=1e-12)
        np.testing.assert_allclose(step.residual, r, atol=1e-12)
        np.testing.assert_allclose(step.f_hat, f_hat, atol=1e-12)
        x_hat, f_hat = p.A @ x_hat + p.B0 @ u + p.B1 @ u_prev + p.Df @ f_hat + g.L @ r, f_hat + g.M @ r
        u_prev = u
