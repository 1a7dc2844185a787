"""Eqs. (5)-(6) as the live loop steps them: reported u(k-1), observe-only, saturation, non-finite reset."""

from __future__ import annotations

import numpy as np

from monitor.model.closed_loop import Gains
from monitor.model.estimator import Estimator
from monitor.model.plant import load_plant

G = Gains(
    L=np.array([[1.8], [1.6]]), M=np.array([[0.9]]), K1=np.array([[-0.26]]), K2=np.array([[0.1]]), K3=np.array([[-1.0]])
)


def _by_hand(p, x, f, u_prev, y, u):
    """Eq. (5) written out: the reference the estimator must match."""
    r = y - p.C @ x
    return p.A @ x + p.B0 @ u + p.B1 @ u_prev + p.Df @ f + G.L @ r, f + G.M @ r


def test_reported_deflection_replaces_the_estimators_own_last_command() -> None:
    p = load_plant("paper-continuous")
    est = Estimator(p, G)
    s = est.initial_state()
    est.step(s, 0, [0.5])
    x, f = s.x_hat.copy(), s.f_hat.copy()
    reported = np.array([7.0])  # the command did not act: the vehicle held 7 deg
    res = est.step(s, 1, [0.4], u_prev=reported)
    u = G.K1 @ [0.4] + G.K2 @ reported + G.K3 @ f
    assert np.allclose(res.u, u)
    x1, f1 = _by_hand(p, x, f, reported, np.array([0.4]), u)
    assert np.allclose(s.x_hat, x1) and np.allclose(s.f_hat, f1) and np.allclose(s.u_prev, u)


def test_observe_only_runs_eq5_with_the_vehicles_own_command() -> None:
    p = load_plant("paper-continuous")
    est = Estimator(p, G)
    s = est.initial_state()
    prev = np.zeros(1)
    for k, (y, u) in enumerate([(0.1, 1.0), (0.3, -2.0), (0.2, 0.5)]):
        x, f = s.x_hat.copy(), s.f_hat.copy()
        res = est.observe(s, k, [y], [u])
        x1, f1 = _by_hand(p, x, f, prev, np.array([y]), np.array([u]))
        assert np.allclose(s.x_hat, x1) and np.allclose(s.f_hat, f1) and res.u[0] == u
        prev = np.array([u])


def test_commands_saturate_at_the_actuator_limit_and_the_observer_uses_the_saturated_value() -> None:
    p = load_plant("paper-continuous")
    assert p.actuator.limit == 30.0
    est = Estimator(p, G)
    s = est.initial_state()
    x, f = s.x_hat.copy(), s.f_hat.copy()
    res = est.step(s, 0, [-500.0])  # K1 y = +130 deg
    assert res.u[0] == 30.0
    x1, _ = _by_hand(p, x, f, np.zeros(1), np.array([-500.0]), np.array([30.0]))
    assert np.allclose(s.x_hat, x1)


def test_a_non_finite_state_is_reset_and_flagged() -> None:
    est = Estimator(load_plant("paper-continuous"), G)
    s = est.initial_state()
    res = est.step(s, 0, [float("nan")])
    assert res.reset and np.all(s.z == 0.0)
    assert not est.step(s, 1, [0.1]).reset


def test_a_command_that_never_acted_is_replaced_by_the_held_deflection_in_the_last_step() -> None:
    """Every command late: the plant only ever sees the held 0; the estimate must match that plant exactly."""
    p = load_plant("paper-continuous")
    cdf = float((p.C @ p.Df)[0, 0])  # a stable observer: the fault-direction deadbeat one
    est = Estimator(p, Gains(L=(p.A + np.eye(2)) @ p.Df / cdf, M=np.array([[1 / cdf]]), K1=G.K1, K2=G.K2, K3=G.K3))
    s = est.initial_state()
    x, f = np.zeros(2), 2.0  # a 2-degree bias from the start, the elevator stuck at its held 0
    for k in range(40):
        y = (p.C @ x)[0]
        est.step(s, k, [y], u_prev=[0.0], applied=None if k == 0 else False)
        x = p.A @ x + (p.Df * f).ravel()
    assert abs(s.f_hat[0] - 2.0) < 1e-6
    s2 = est.initial_state()
    x = np.zeros(2)
    for k in range(40):  # without being told, the same data leaves a biased estimate
        est.step(s2, k, [(p.C @ x)[0]], u_prev=[0.0])
        x = p.A @ x + (p.Df * f).ravel()
    assert abs(s2.f_hat[0] - 2.0) > 0.1
