"""The demo's pieces without daemons: the Monte-Carlo's actuator, Fig. 5's steady state, the design list."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from monitor.closed_loop import steady_state
from monitor.demo import montecarlo
from monitor.demo.methods import METHODS, look
from monitor.demo.steady import held_output_steady_state, q_caption
from monitor.errors import UserError
from monitor.wire.specs import parse_delay_spec, parse_fault_spec
from sim_vehicle.wind import parse_wind_spec
from tests.designs import designed


def _run(plant, gains, seed: int) -> montecarlo.Trace:
    return montecarlo.simulate(plant, gains, 100, parse_fault_spec("bias:2@20"), parse_delay_spec("uniform:0:0.46", seed),
                               parse_wind_spec("paper", plant.h, seed).values())


def test_monte_carlo_clips_the_elevator_as_the_live_vehicle_does():
    plant, result = designed("paper-continuous", "separate")
    assert plant.actuator.limit == 30.0
    for seed in range(3):
        trace = _run(plant, result.gains, seed)
        assert np.max(np.abs(trace.u)) == pytest.approx(30.0)  # the unstable loop swings between the limits
        assert np.max(np.abs(trace.alpha)) < 30.0  # bounded, comparable to the live run (12-15 deg), not 8e11
    free = dataclasses.replace(plant, actuator=dataclasses.replace(plant.actuator, limit=None))
    assert np.max(np.abs(_run(free, result.gains, 0).alpha)) > 1e6  # what an unlimited elevator would claim
    assert montecarlo.actuator(plant, np.array([45.0]))[0] == 30.0


def test_monte_carlo_refuses_an_actuator_it_does_not_model():
    plant, result = designed("paper-continuous", "separate")
    slewing = dataclasses.replace(plant, actuator=dataclasses.replace(plant.actuator, rate_limit=60.0))
    with pytest.raises(UserError, match="rate-limited"):
        _run(slewing, result.gains, 0)


def test_fig5_pitch_rate_offset_is_the_plants_steady_state():
    plant, result = designed("paper-continuous", "certified")
    held = held_output_steady_state(plant, 2.0)
    assert held.x[0] == pytest.approx(0.0, abs=1e-12)
    assert held.x[1] == pytest.approx(-0.579, abs=5e-4) and held.u[0] == pytest.approx(-0.880, abs=5e-4)
    S_x, S_u = steady_state(plant, result.gains)  # the certified loop's own steady state agrees
    assert 2.0 * S_x[:, 0] == pytest.approx(held.x, abs=1e-6) and 2.0 * S_u[0, 0] == pytest.approx(held.u[0], abs=1e-6)
    caption, q = q_caption(plant, parse_fault_spec("bias:2@20"), 100)
    assert q == pytest.approx(held.x[1]) and "q = -0.58 deg/s" in caption and "u = -0.88 deg" in caption
    assert q_caption(plant, parse_fault_spec("ramp:0.1@20"), 100) == ("", None)  # no constant fault: no claim


def test_designs_are_one_list_and_any_name_gets_a_distinct_look():
    from monitor.demo.orchestrate import DemoOptions

    assert DemoOptions().methods == METHODS
    looks = [look(m) for m in METHODS]
    assert len({(s.colour, s.line) for s in looks}) == len(METHODS)
    assert look("some-future-design") not in looks
