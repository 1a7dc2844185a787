"""Delays past one sample: the lagged model against a direct simulation of the arrivals, and its polytope.

The reference here shares nothing with ``monitor.model.long_delay`` but the plant's continuous matrices: it
integrates ``x' = A_c x + B_c u`` exactly over each piece of the interval on which one command is in force,
with the link rule written out as events (a command acts when it arrives unless a newer one already acted).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import linprog

from monitor.errors import UserError
from monitor.model.delay_model import b0_of_tau, b0_polytope, realization
from monitor.model.plant import plant_from_table

CONTINUOUS = {
    "form": "continuous",
    "h": 0.05,
    "A_c": [[-1.2, 0.9], [-4.0, -1.5]],
    "B_c": [[-0.1], [-6.0]],
    "D_cf": [[-0.1], [-6.0]],
    "D_cd": [[0.0], [1.0]],
    "C": [[1.0, 0.0], [0.0, 1.0]],
}


def lagged(tau_min: float, tau_max: float, **over):
    return plant_from_table({**CONTINUOUS, "tau_min": tau_min, "tau_max": tau_max, **over}, "test")


def step_exact(A_c, B_c, x, pieces, h, w=None):
    """x after one interval of ``pieces`` = [(start, u)] (starts ascending from 0), integrated exactly; ``w``: a
    constant input held over the interval (a fault through ``D_cf``)."""
    n = A_c.shape[0]
    bounds = [s for s, _ in pieces] + [h]
    held = np.zeros(n) if w is None else np.asarray(w, dtype=float)
    for (start, u), end in zip(pieces, bounds[1:], strict=True):
        block = np.zeros((n + 1, n + 1))
        block[:n, :n] = A_c
        block[:n, n:] = B_c @ np.atleast_1d(u).reshape(-1, 1) + held.reshape(-1, 1)
        E = expm(block * (end - start))
        x = E[:n, :n] @ x + E[:n, n]
    return x


def in_force(arrivals: dict[int, float], k: int, h: float, u: dict[int, float]) -> list[tuple[float, float]]:
    """The pieces of interval k under the link rule: each command acts on arrival unless a newer one acted."""
    t0 = k * h
    events = sorted((t, i) for i, t in arrivals.items() if t < t0 + h)
    newest, current, pieces = -(10**9), 0.0, []
    for t, i in events:
        if i <= newest:
            continue  # stale: a newer command already acted
        newest = i
        if t <= t0:
            current = u[i]
        else:
            pieces.append((t - t0, u[i]))
    return [(0.0, current)] + pieces


@pytest.mark.parametrize("tau_min, tau_max", [(0.05, 0.12), (0.0, 0.07), (0.06, 0.15), (0.1, 0.1)])
def test_the_lagged_model_is_the_plant_under_any_arrival_pattern(tau_min, tau_max):
    plant = lagged(tau_min, tau_max)
    base = plant.lags.base
    A_c, B_c, h = base.continuous.A_c, base.continuous.B_c, plant.h
    rng = np.random.default_rng(7)
    steps = 40
    u = {i: float(rng.normal()) for i in range(-10, steps)}
    taus = {i: float(rng.uniform(tau_min, tau_max)) for i in range(-10, steps)}
    arrivals = {i: i * h + taus[i] for i in u}
    first, last = plant.lags.first, plant.lags.last
    vertices = np.array([v.ravel() for v in b0_polytope(plant)])
    x = np.array([0.3, -0.2])
    for k in range(0, steps - 1):
        pieces = in_force(arrivals, k, h, u)
        x_next = step_exact(A_c, B_c, x, pieces, h)
        # a_j: when u(k-j) or a newer command first acted in the interval (0: before it)
        point = []
        for j in range(first, last + 1):
            times = [arrivals[i] - k * h for i in range(k - j, k + 1) if arrivals[i] < (k + 1) * h]
            a = min(max(min(times, default=h), 0.0), h)
            point.append(_G(A_c, B_c, h, a))
        point = np.vstack(point)
        A_t, B0_t, B1_t = realization(plant, point)
        z = np.concatenate([x, [u[k - j] for j in range(2, last + 2)]])
        predicted = A_t @ z + B0_t[:, 0] * u[k] + B1_t[:, 0] * u[k - 1]
        assert np.allclose(predicted[:2], x_next, atol=1e-12), k
        assert np.allclose(predicted[2:], [u[k - j] for j in range(1, last + 1)])  # the history shifts
        assert _inside(vertices, point.ravel()), f"the point of sample {k} is outside the polytope"
        x = x_next


def _G(A_c, B_c, h, a):
    n = A_c.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = A_c
    block[:n, n:] = np.eye(n)
    return expm(block * (h - a))[:n, n:] @ B_c


def _inside(vertices: np.ndarray, point: np.ndarray) -> bool:
    k = len(vertices)
    res = linprog(
        np.zeros(k),
        A_eq=np.vstack([vertices.T, np.ones((1, k))]),
        b_eq=np.append(point, 1.0),
        bounds=[(0, None)] * k,
        method="highs",
    )
    return res.status == 0


def test_a_short_interval_is_the_ordinary_plant_and_a_constant_delay_the_nominal():
    short = lagged(0.0, 0.04)
    assert short.lags is None and short.n == 2
    long = lagged(0.06, 0.08)
    assert long.lags is not None and long.n == 2 + 1  # u(k-2) joins the state
    A_t, B0_t, B1_t = realization(long, b0_of_tau(long, long.tau_bar))
    assert np.allclose(A_t, long.A) and np.allclose(B0_t, long.B0) and np.allclose(B1_t, long.B1)
    assert np.allclose(long.B0, 0.0)  # no command acts within its own interval when tau_min >= h


def test_a_discrete_plant_file_reaches_past_h_through_its_continuous_reconstruction():
    exact = lagged(0.05, 0.09)
    base = exact.lags.base
    discrete = plant_from_table(
        {
            "form": "discrete",
            "h": 0.05,
            "tau_min": 0.05,
            "tau_max": 0.09,
            "A": base.A.tolist(),
            "B0": base.B0.tolist(),
            "B1": base.B1.tolist(),
            "Df": base.Df.tolist(),
            "Dd": base.Dd.tolist(),
            "C": base.C.tolist(),
        },
        "d",
    )
    assert np.allclose(discrete.A, exact.A, atol=1e-9) and np.allclose(discrete.B1, exact.B1, atol=1e-9)


def test_an_interval_spanning_too_many_samples_is_one_line():
    with pytest.raises(UserError, match="'tau_min'/'tau_max'.*at most 3") as err:
        lagged(0.0, 0.2)
    assert "\n" not in str(err.value)


# -- the loop past one sample, designed and certified, flown on the vehicle's event simulation ---------------

LONG_DELAY_PLANT = str(Path(__file__).parents[1] / "docs" / "examples" / "paper-continuous-long-delay.toml")


def test_a_certified_loop_holds_with_every_command_one_to_two_and_a_half_samples_late():
    """uniform:1:2.4 at h = 1 s: no command ever acts in its own interval. The design's certificate is checked
    by verify; the estimate on the vehicle's exact simulation settles within 5 % and stays there."""
    from monitor.checks.verify import verify_gains
    from monitor.jsbsim_flights import ClosedLoop
    from monitor.model.estimator import Estimator
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec
    from sim_vehicle.simulation import Simulation
    from tests.designs import designed

    plant, result = designed(LONG_DELAY_PLANT, "certified")
    assert plant.lags is not None and (plant.lags.first, plant.lags.last) == (1, 2)
    verdict = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    assert verdict.stable and verdict.certificate_valid and verdict.bound_holds, verdict
    # the monitor's estimator answering each sample when it is sent: the drawn delay is the whole delay
    loop = ClosedLoop(Estimator(plant, result.gains))
    loop.fly(
        Simulation(
            plant=plant.physical,
            sink=loop,
            steps=70,
            fault=parse_fault_spec("bias:2@20"),
            delay=parse_delay_spec("uniform:1:2.4", seed=3),
        )
    )
    taus = [p["tau"] for p in loop.truth.values() if p["tau"] is not None]
    assert len(taus) > 50 and min(taus) >= 1.0 and max(taus) > 2.0  # every command acted one to 2.4 samples late
    assert sum(p["in_force"] < p["k"] - 1 for p in loop.truth.values()) > 10  # often u(k-2) or older was in force
    errors = [abs(loop.f_hat[k] - 2.0) for k in range(26, 70)]
    # within 2 % from 6 samples after onset (measured 1.1 %; an estimator that took the vehicle's report for
    # u(k-1), as within one sample, stays 4 % off: the report is whichever older command is in force)
    assert max(errors) <= 0.02 * 2.0, max(errors)
    assert max(abs(loop.f_hat[k]) for k in range(0, 20)) < 0.05  # nothing before the onset


def test_the_certified_loop_holds_on_an_independent_simulation_of_the_link_rule():
    """The same design flown by this file's own exact integration and link rule, not by sim-vehicle's: every
    command 1 to 2.4 samples late (seeded numpy), the newest arrived command in force, a 2-deg bias at k = 20."""
    from monitor.model.estimator import Estimator
    from tests.designs import designed

    plant, result = designed(LONG_DELAY_PLANT, "certified")
    model, h = plant.physical.continuous, plant.h
    est = Estimator(plant, result.gains)
    state = est.initial_state()
    rng = np.random.default_rng(11)
    x, u, arrivals, f_hat = np.zeros(plant.physical.n), {}, {}, {}
    for k in range(70):
        step = est.step(state, k, plant.physical.C @ x)  # no report: past one sample the estimator keeps its own
        u[k], f_hat[k] = float(step.u[0]), float(step.f_hat[0])
        arrivals[k] = k * h + rng.uniform(1.0, 2.4)
        fault = 2.0 if k >= 20 else 0.0
        x = step_exact(model.A_c, model.B_c, x, in_force(arrivals, k, h, u), h, w=model.D_cf[:, 0] * fault)
    assert max(abs(f_hat[k] - 2.0) for k in range(26, 70)) <= 0.02 * 2.0
    assert max(abs(f_hat[k]) for k in range(20)) < 0.05


def test_margin_bisects_past_one_sample_and_its_design_verifies_there():
    """A stable 1-state plant takes any delay: the margin reaches the search's top, 1.9 samples, with a design
    whose certificate verify accepts on the lagged plant."""
    from monitor.checks.margin import delay_margin
    from monitor.checks.verify import verify_gains

    plant = plant_from_table(
        {
            "form": "continuous",
            "h": 1.0,
            "tau_min": 0.0,
            "tau_max": 0.3,
            "A_c": [[-1.0]],
            "B_c": [[1.0]],
            "D_cf": [[1.0]],
            "D_cd": [[1.0]],
            "C": [[1.0]],
        },
        "tiny",
    )
    margin = delay_margin(plant, tolerance=0.2, curve_points=2, up_to=1.9)
    assert margin.tau_max == pytest.approx(1.9) and margin.plant.lags is not None
    result = margin.design
    verdict = verify_gains(margin.plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    assert verdict.stable and verdict.certificate_valid, verdict
