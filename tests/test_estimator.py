"""Eqs. (5)-(6) as the live loop steps them: reported u(k-1), observe-only, saturation, non-finite reset."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.model.closed_loop import Gains, fault_compensation
from monitor.model.estimator import Estimator, report_pole
from monitor.model.known_inputs import KnownInputs
from monitor.model.plant import Plant, load_plant

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


def _random_model(rng: np.random.Generator, known: bool) -> tuple[Plant, Gains]:
    """A stable random plant (n 2-5, q 1-2, m 1-2, l 1-3) with random gains, and a known-input Gamma if asked."""
    n, q, m, l = (int(rng.integers(lo, hi + 1)) for lo, hi in ((2, 5), (1, 2), (1, 2), (1, 3)))
    A = rng.normal(size=(n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    mats = {name: rng.normal(size=shape) for name, shape in (("B0", (n, m)), ("B1", (n, m)), ("C", (l, n)))}
    Df = rng.normal(size=(n, q))
    ki = KnownInputs(terms=(), gamma=rng.normal(size=(n, n)), index={}, names=(), signals=()) if known else None
    plant = Plant("random", "discrete", 0.02, 0.0, 0.01, A, Df=Df, Dd=np.zeros((n, 1)), known_inputs=ki, **mats)
    gains = Gains(  # small: the random loop stays near its inputs' size over the run (a relative 1e-12 means it)
        L=0.05 * rng.normal(size=(n, l)),
        M=0.05 * rng.normal(size=(q, l)),
        K1=0.3 * rng.normal(size=(m, l)),
        K2=0.1 * rng.normal(size=(m, m)),
        K3=0.3 * rng.normal(size=(m, q)),
    )
    return plant, gains


class _Reference:
    """The module docstring's equations in numpy, one vehicle: what the estimator's float loops must equal."""

    def __init__(self, p: Plant, g: Gains, lim: float, u0: np.ndarray, keep: float) -> None:
        self.p, self.g, self.lo, self.hi, self.keep = p, g, -lim - u0, lim - u0, keep
        self.G = fault_compensation(p)
        self.lim = lim
        self.x, self.f, self.u = np.zeros(p.n), np.zeros(p.q), np.zeros(p.m)
        self.k: int | None = None
        self.f_rep = np.zeros(p.q)

    def advance(self, k: int, u_prev, applied) -> None:
        p, gap = self.p, 0 if self.k is None else k - self.k - 1
        self.gap = gap
        for _ in range(gap):  # lost samples: no innovation, the actuator held u(k-1)
            self.x = p.A @ self.x + p.Df @ self.f + (p.B0 + p.B1) @ self.u
        if u_prev is not None:
            held = np.asarray(u_prev, dtype=float)
            if applied is False:  # the step (and the predictions since) acted with the held deflection
                delta = held - self.u
                correction = p.B0 @ delta
                for _ in range(gap):
                    correction = p.A @ correction + (p.B0 + p.B1) @ delta
                self.x = self.x + correction
            self.u = held

    def finish(self, k: int, y, u_now, known) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        p, g = self.p, self.g
        r = np.asarray(y) - p.C @ self.x
        x_k, f_k = self.x, self.f
        self.x = p.A @ x_k + p.B0 @ u_now + p.B1 @ self.u + p.Df @ f_k + g.L @ r
        if known is not None:
            self.x = self.x + p.known_inputs.gamma @ np.asarray(known)
        self.f, self.u, self.k = f_k + g.M @ r, np.asarray(u_now, dtype=float), k
        self.f_rep = self.keep * self.f_rep + (1.0 - self.keep) * f_k if self.keep else f_k
        return u_now, x_k, self.f_rep, r

    def step(self, k, y, u_prev, applied, known):
        self.advance(k, u_prev, applied)
        u = np.clip(self.g.K1 @ y + self.g.K2 @ self.u + self.g.K3 @ self.f, self.lo, self.hi)
        return self.finish(k, y, u, known)

    def resume(self, y, reported) -> None:
        """Observe-only and compensate, after lost samples: x from the outputs where C gives it, u(k-1) = now's."""
        if self.gap:
            C = self.p.C
            if C.shape[0] == C.shape[1] and np.linalg.cond(C) < 1e8:
                self.x = np.linalg.solve(C, np.asarray(y))
            self.u = np.asarray(reported, dtype=float)

    def observe(self, k, y, u_now, u_prev, known):
        self.advance(k, u_prev, None)
        self.resume(y, u_now)
        return self.finish(k, y, np.asarray(u_now), known)

    def compensate(self, k, y, u_total, c_prev, known):
        self.advance(k, u_total, None)
        self.resume(y, u_total)
        comp = np.clip(self.G @ self.f, -self.lim, self.lim)
        return self.finish(k, y, np.asarray(u_total) - c_prev + comp, known), comp


@pytest.mark.parametrize("mode", ["step", "observe", "compensate"])
def test_the_float_loops_equal_the_equations_in_numpy_on_random_models(mode: str) -> None:
    """Random plants and gains, lost samples (short gaps in floats, long ones by a matrix power; observe-only resumes
    from the outputs), commands that did not act, known inputs and a low-passed report: every output and the state
    equal numpy's to 1e-12."""
    rng = np.random.default_rng(7)
    for trial in range(12):
        plant, gains = _random_model(rng, known=trial % 2 == 0)
        u0 = rng.normal(size=plant.m)
        tc = 0.1 if trial % 3 == 0 else None
        est = Estimator(plant, gains, u_limit=2.5, u0=u0, fault_time_constant=tc)
        ref = _Reference(plant, gains, 2.5, u0, report_pole(plant.h, tc))
        s = est.initial_state()
        c_prev = np.zeros(plant.m)
        k = 0
        for i in range(60):
            k += 1 + int(rng.choice([0, 0, 0, 0, 1, 3, 10]))  # gaps of 0, 1, 3 and 10 lost samples
            y = list(rng.normal(size=plant.l))
            known = list(rng.normal(size=plant.n)) if plant.known_inputs is not None and i % 3 else None
            u_prev = list(rng.normal(size=plant.m)) if i % 4 else None
            if mode == "step":
                applied = [None, True, False][i % 3] if u_prev is not None else None
                res = est.step(s, k, y, u_prev=u_prev, applied=applied, known=known)
                expected = ref.step(k, y, u_prev, applied, known)
            elif mode == "observe":
                u_now = list(rng.normal(size=plant.m))
                res = est.observe(s, k, y, u_now, u_prev=u_prev, known=known)
                expected = ref.observe(k, y, u_now, u_prev, known)
            else:
                u_total = list(rng.normal(size=plant.m))
                res, comp = est.compensate(s, k, y, u_total, list(c_prev), known=known)
                expected, ref_comp = ref.compensate(k, y, u_total, c_prev, known)
                assert np.allclose(comp, ref_comp, rtol=1e-12, atol=1e-12)
                c_prev = ref_comp
            for got, want in zip((res.u, res.x_hat, res.f_hat, res.residual), expected, strict=True):
                assert np.allclose(got, want, rtol=1e-12, atol=1e-12), (trial, i, got, want)
            assert res.u.tolist() == res.u_values and res.f_hat.tolist() == res.f_hat_values
            assert np.allclose(s.z, np.concatenate([ref.x, ref.f, ref.u]), rtol=1e-12, atol=1e-12)


def test_the_state_array_a_caller_changes_in_place_is_what_the_next_step_reads() -> None:
    est = Estimator(load_plant("paper-continuous"), G)
    a, b = est.initial_state(), est.initial_state()
    est.step(a, 0, [0.5])
    est.step(b, 0, [0.5])
    a.z[0] += 1.0  # handed out, then changed in place (a test rig, a re-base)
    b.z = b.z + np.eye(len(b.z))[0]  # replaced
    assert est.step(a, 1, [0.4]).residual_values == est.step(b, 1, [0.4]).residual_values
    assert a.z.tolist() == b.z.tolist()
