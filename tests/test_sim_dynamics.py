"""Exact integration (sim_vehicle/dynamics.py) against a brute-force fine integration with scipy.

The reference solves the ODE with solve_ivp at tight tolerances, one call per stretch where the input is
smooth (a discontinuity inside an adaptive step would only test the step control), and an independent
formulation of the actuator.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from monitor.model.plant import Actuator, load_plant
from sim_vehicle.dynamics import Airframe, segment_matrices

PLANT = load_plant("paper-continuous")
MODEL = PLANT.continuous
TOL = dict(rtol=1e-11, atol=1e-13, method="DOP853")


def brute(x0, pieces, w=None):
    """Integrate x' = A x + B u(t) + w through ``pieces`` = [(t0, t1, u(t)), ...] (``w``: zero by default)."""
    x = np.asarray(x0, float)
    B = MODEL.B_c[:, 0]
    w = np.zeros(2) if w is None else w
    for t0, t1, u in pieces:
        # solve_ivp calls the right-hand side only within this iteration; u is bound explicitly all the same
        sol = solve_ivp(lambda t, z, u=u: MODEL.A_c @ z + B * u(t) + w, (t0, t1), x, **TOL)
        x = sol.y[:, -1]
    return x


def test_segment_matrices_are_the_ramp_integrals():
    T = 0.37
    phi, g1, g2 = segment_matrices(MODEL.A_c, T)
    assert np.allclose(phi, expm(MODEL.A_c * T), atol=1e-14)
    # Gamma1 and Gamma2 by the ODEs they satisfy: G1' = e^{At}, G2' = G1
    sol = solve_ivp(
        lambda t, z: np.concatenate([(MODEL.A_c @ z[:4].reshape(2, 2)).ravel(), z[:4], z[4:8]]),
        (0, T),
        np.concatenate([np.eye(2).ravel(), np.zeros(8)]),
        **TOL,
    )
    assert np.allclose(g1, sol.y[4:8, -1].reshape(2, 2), atol=1e-10)
    assert np.allclose(g2, sol.y[8:12, -1].reshape(2, 2), atol=1e-10)


def test_command_switching_mid_interval_matches_brute_force():
    x0 = [0.3, -0.2]
    f, d = np.array([2.0]), np.array([0.05])
    w = MODEL.D_cf @ f + MODEL.D_cd @ d
    air = Airframe(MODEL, x=x0)
    air.command(1.5)
    air.set_interval(f, d)
    air.advance_to(0.2834)
    air.command(-4.0)  # the new command reaches the actuator mid-interval
    air.advance_to(1.0)
    ref = brute(x0, [(0, 0.2834, lambda t: 1.5), (0.2834, 1.0, lambda t: -4.0)], w)
    assert np.allclose(air.x, ref, atol=1e-10)


def test_airframe_reproduces_the_papers_discrete_model():
    from monitor.model.discretize import discretize

    tau, u_prev, u_new = 0.31, 1.2, -0.7
    f, d = np.array([2.0]), np.array([0.01])
    x0 = np.array([0.5, 0.1])
    air = Airframe(MODEL, x=x0)
    air.command(u_prev)
    air.set_interval(f, d)
    air.advance_to(tau)
    air.command(u_new)
    air.advance_to(PLANT.h)
    D = discretize(MODEL, PLANT.h, tau)
    expected = D.A @ x0 + D.B0[:, 0] * u_new + D.B1[:, 0] * u_prev + D.Df @ f + D.Dd @ d
    assert np.allclose(air.x, expected, atol=1e-12)


def test_deflection_limit_clips_the_command():
    air = Airframe(MODEL, Actuator(limit=30.0))
    air.command(55.0)
    assert air.position == 30.0
    air.command(-99.0)
    assert air.position == -30.0


def test_rate_limit_slews_and_matches_brute_force():
    rate = 10.0  # deg/s: 0 -> 4 deg takes 0.4 s, then holds
    air = Airframe(MODEL, Actuator(limit=30.0, rate_limit=rate))
    air.advance_to(0.1)
    air.command(4.0)
    air.advance_to(0.3)
    assert air.position == pytest.approx(2.0)
    air.advance_to(1.0)
    assert air.position == 4.0
    ref = brute([0, 0], [(0, 0.1, lambda t: 0.0), (0.1, 0.5, lambda t: rate * (t - 0.1)), (0.5, 1.0, lambda t: 4.0)])
    assert np.allclose(air.x, ref, atol=1e-10)


def test_loe_scales_the_effect_not_the_measured_position():
    a, b = Airframe(MODEL), Airframe(MODEL)
    a.command(3.0)
    a.set_interval([0.0], [0.0], effectiveness=0.5)
    b.command(1.5)
    a.advance_to(1.0)
    b.advance_to(1.0)
    assert a.position == 3.0 and np.allclose(a.x, b.x, atol=1e-14)


def test_stuck_freezes_the_surface_where_it_is_or_at_a_value():
    air = Airframe(MODEL)
    air.command(2.0)
    air.set_interval([0.0], [0.0], stuck=True)
    air.command(-10.0)
    air.advance_to(1.0)
    assert air.position == 2.0
    ref = brute([0, 0], [(0, 1.0, lambda t: 2.0)])
    assert np.allclose(air.x, ref, atol=1e-10)
    air.set_interval([0.0], [0.0], stuck=False)
    assert air.position == -10.0  # released: the servo goes to the command it kept receiving
    air.command(-1.0)
    assert air.position == -1.0
    air.set_interval([0.0], [0.0], stuck=True, stuck_value=5.0)
    assert air.position == 5.0


def test_time_cannot_go_backwards():
    air = Airframe(MODEL)
    air.advance_to(1.0)
    with pytest.raises(ValueError):
        air.advance_to(0.5)
