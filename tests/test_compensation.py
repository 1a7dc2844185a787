"""The autopilot flies, the monitor compensates (``fault-monitor run --compensate``): the estimator's step.

The plant is integrated here with its own discrete matrices; a vehicle autopilot ``a(k) = K_ap y(k)`` (not the
design's controller) acts from the sampling instant, and the compensation ``c(k)`` the monitor returns acts
after the link's delay, from ``k h + tau``: ``x+ = A x + (B0 + B1) a(k) + B0 c(k) + B1 c(k-1) + Df f``. The
monitor sees only what the vehicle reports, the deflection in force at each instant ``a(k) + c(k-1)``.
"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.model.closed_loop import fault_compensation
from monitor.model.estimator import Estimator
from tests.designs import designed

K_AP = -0.2  # the vehicle's own autopilot (any stabilising gain: the paper's plant is open-loop stable)
ONSET, BIAS, STEPS = 20, 2.0, 60


def _fly(compensate: bool):
    plant, result = designed("paper-continuous", "certified")
    g = result.gains
    est = Estimator(plant, g)
    s = est.initial_state()
    A, B0, B1, C, Df = plant.A, plant.B0, plant.B1, plant.C, plant.Df
    x = np.zeros(plant.n)
    c_prev = [0.0]
    # an independent observer, from the equations of the docstring, with the same inputs
    xh, fh = np.zeros(plant.n), np.zeros(plant.q)
    rows = []
    for k in range(STEPS):
        y = C @ x
        a = K_AP * float(y[0])
        total = a + c_prev[0]  # what the vehicle reports at instant k
        if compensate:
            res, comp = est.compensate(s, k, y, [total], c_prev)
        else:
            res, comp = est.observe(s, k, y, [total], u_prev=[total]), [0.0]
        expected_c = (
            float(np.clip(fault_compensation(plant) @ fh, -plant.actuator.limit, plant.actuator.limit)[0])
            if compensate
            else 0.0
        )
        rows.append((k, float(y[0]), float(res.f_hat[0]), comp[0], expected_c, float(fh[0])))
        r = y - C @ xh
        xh = A @ xh + (B0 + B1).ravel() * a + B0.ravel() * comp[0] + B1.ravel() * c_prev[0] + Df @ fh + g.L @ r
        fh = fh + g.M @ r
        f = BIAS if k >= ONSET else 0.0
        x = A @ x + (B0 + B1).ravel() * a + B0.ravel() * comp[0] + B1.ravel() * c_prev[0] + Df.ravel() * f
        c_prev = comp
    return rows


def test_the_compensation_is_the_fault_term_times_the_estimate_of_the_independent_observer() -> None:
    rows = _fly(compensate=True)
    for k, _y, f_hat, comp, expected, fh_indep in rows:
        assert f_hat == pytest.approx(fh_indep, abs=1e-9), k
        assert comp == pytest.approx(expected, abs=1e-9), k
    assert any(abs(r[3]) > 0.05 for r in rows if r[0] > ONSET + 2)  # it really compensates after the onset


def test_with_the_delay_split_modelled_the_estimate_settles_on_the_bias() -> None:
    rows = _fly(compensate=True)
    late = [f for k, _y, f, *_ in rows if k >= ONSET + 8]
    assert max(abs(f - BIAS) for f in late) < 0.05 * BIAS, late
    assert max(abs(f) for k, _y, f, *_ in rows if k < ONSET) < 1e-9  # no fault, no estimate


def test_the_compensation_takes_the_fault_s_offset_out_of_the_output() -> None:
    without = _fly(compensate=False)
    with_c = _fly(compensate=True)
    offset = abs(without[-1][1])
    assert offset > 0.2  # the bias moves the output the autopilot alone holds
    assert abs(with_c[-1][1]) < 0.5 * offset, (with_c[-1][1], offset)


def test_for_an_actuator_fault_the_compensation_is_minus_the_estimate() -> None:
    from monitor.model.plant import parse_plant
    from tests.aircraft_files import AIRCRAFT_PLANT

    plant = parse_plant(AIRCRAFT_PLANT, "aircraft")  # D_cf = B_c: an elevator bias
    assert fault_compensation(plant) == pytest.approx(-np.eye(1), abs=1e-9)


def _fly_with_lost_compensations(report: bool, lost: range) -> list[tuple[int, float]]:
    """As ``_fly``, but the compensations answering the samples in ``lost`` never act (late: the vehicle holds the
    one in force); ``report``: the vehicle reports the compensation in force and the estimator is given it."""
    plant, result = designed("paper-continuous", "certified")
    est = Estimator(plant, result.gains)
    s = est.initial_state()
    A, B0, B1, C, Df = plant.A, plant.B0, plant.B1, plant.C, plant.Df
    x = np.zeros(plant.n)
    in_force, sent = 0.0, [0.0]
    rows = []
    for k in range(STEPS + 40):
        y = C @ x
        a = K_AP * float(y[0])
        total = a + in_force
        res, comp = est.compensate(s, k, y, [total], sent, c_in_force=[in_force] if report else None)
        rows.append((k, float(res.f_hat[0])))
        acting = in_force if k in lost else comp[0]  # what acts from k h + tau
        f = BIAS if k >= ONSET else 0.0
        x = A @ x + (B0 + B1).ravel() * a + B0.ravel() * acting + B1.ravel() * in_force + Df.ravel() * f
        in_force, sent = acting, comp
    return rows


def test_a_run_of_late_compensations_reported_in_force_is_no_phantom_fault() -> None:
    """Twenty compensations in a row that never act, from the bias's onset: told which one is in force,
    the estimator corrects each step as the contract's lost command and f_hat stays on the bias; assuming they
    acted (the vehicle does not report it), each is a phantom input and f_hat leaves the bias."""
    lost = range(ONSET + 1, ONSET + 21)  # while f_hat (so the compensation) is still moving
    told = _fly_with_lost_compensations(report=True, lost=lost)
    blind = _fly_with_lost_compensations(report=False, lost=lost)
    settled = [f for k, f in told if k >= ONSET + 8]
    assert max(abs(f - BIAS) for f in settled) < 0.05 * BIAS, settled
    assert max(abs(f - BIAS) for k, f in blind if k >= ONSET + 8) > 0.1 * BIAS
    # and with nothing lost the report changes nothing (every compensation it reports is the one sent)
    assert [f for _k, f in _fly_with_lost_compensations(True, range(0))] == pytest.approx(
        [f for _k, f in _fly_with_lost_compensations(False, range(0))], abs=1e-12
    )


def test_observe_only_after_lost_samples_reads_the_state_from_the_outputs_not_a_phantom_fault() -> None:
    """Observe-only, the vehicle's own controller moving the elevator while ten samples are lost: the prediction
    held the last deflection reported, so the first innovation read the controller's moves as a fault (a spike);
    with the state read from the outputs (``C = I``) and u(k-1) taken as the deflection reported now, f_hat stays
    near where it was (zero: there is no fault). The same flight without the gap: zero throughout (exact model)."""
    from monitor.model.closed_loop import Gains
    from monitor.model.plant import parse_plant
    from tests.envelope_files import short_period

    plant = parse_plant(short_period(3.8, 0.0, -7.1), "sp.toml")
    gains = Gains(
        L=0.5 * plant.A, M=np.array([[0.1, 0.1]]), K1=np.zeros((1, 2)), K2=np.zeros((1, 1)), K3=np.zeros((1, 1))
    )

    def fly(lost: range) -> list[float]:
        est = Estimator(plant, gains)
        s = est.initial_state()
        x, u_prev, f_hat = np.zeros(2), 0.0, []
        for k in range(60):
            u = 0.8 * np.sin(0.3 * k)  # the vehicle's own controller, unknown to the monitor while samples are lost
            if k not in lost:
                f_hat.append(float(est.observe(s, k, x.copy(), [u]).f_hat[0]))
            x = plant.A @ x + plant.B0.ravel() * u + plant.B1.ravel() * u_prev
            u_prev = u
        return f_hat

    assert max(map(abs, fly(range(0)))) < 1e-9
    # what is left is u(k-1), unknown after the gap, taken as u(k): 0.014 here (without reading the state from the
    # outputs and that guess: 1.56, one sample)
    assert max(map(abs, fly(range(30, 40)))) < 0.05
