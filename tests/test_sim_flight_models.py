"""One flight-model interface, two implementations: the linear plant and the JSBSim aircraft behind the same
event simulation, servo, faults, excitation and telemetry (sim_vehicle/flight_model.py)."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.config_file import parse_args_with_config
from monitor.errors import UserError
from monitor.model.plant import load_plant
from monitor.wire.specs import Excitation, parse_delay_spec, parse_excite_spec, parse_fault_spec
from sim_vehicle.cli import build_parser
from sim_vehicle.config import settings_from_args
from sim_vehicle.dynamics import Airframe, LinearFlightModel
from sim_vehicle.flight_model import FlightModel
from sim_vehicle.jsbsim_model import AircraftSpec, JSBSimFlightModel
from sim_vehicle.simulation import Simulation
from tests.sim_recorder import Recorder

PLANT = load_plant("paper-continuous")
CONTRACT_KEYS = {"sysid", "k", "t", "x", "f", "d", "tau"}


def models() -> list[FlightModel]:
    return [LinearFlightModel.from_plant(PLANT), JSBSimFlightModel(AircraftSpec("c172p"))]


def run(model: FlightModel, steps: int, **kw) -> tuple[Simulation, Recorder]:
    rec = Recorder()
    plant = PLANT if isinstance(model, LinearFlightModel) else None
    sim = Simulation(plant, rec, steps=steps, model=model, delay=parse_delay_spec("const:0.01"), **kw)
    while not sim.done:
        sim.run_until(sim.next_time())
    return sim, rec


def test_both_models_are_flight_models_and_the_same_simulation_flies_them():
    for model in models():
        assert isinstance(model, FlightModel)
        assert len(model.state()) == len(model.state_names) and model.t == 0.0
        sim, rec = run(model, 20, fault=parse_fault_spec("bias:1@5"))
        assert len(rec.samples) == 20 and rec.heartbeats >= 1
        assert all(CONTRACT_KEYS <= set(t) for t in rec.truth) and [t["k"] for t in rec.truth] == list(range(20))
        assert all(len(t["x"]) == len(model.state_names) for t in rec.truth)
        assert rec.truth[10]["f"] == [1.0] and model.t == pytest.approx(20 * model.h)
        # before any command the surface holds the trim deflection (0 for the deviation model)
        assert rec.samples[3].elevator_deg == pytest.approx(model.trim_deflection)
        model.close()


def test_the_linear_model_behind_the_servo_is_the_old_exact_integrator():
    """Airframe(ContinuousModel) builds the linear model itself: the constructor the old tests use."""
    a = Airframe(PLANT.continuous, PLANT.actuator, x=[1.0, 0.0])
    b = Airframe(LinearFlightModel(PLANT.continuous, PLANT.h, PLANT.actuator, x=[1.0, 0.0]))
    for air in (a, b):
        air.set_interval([2.0], [0.01])
        air.command(50.0)  # clipped at the plant's 30 deg
        air.advance_to(0.7)
    assert a.position == b.position == 30.0 and np.array_equal(a.x, b.x)
    with pytest.raises(ValueError):
        Airframe(LinearFlightModel(PLANT.continuous), PLANT.actuator)


def test_the_aircraft_servo_clips_to_the_asymmetric_travel_the_probe_found():
    model = JSBSimFlightModel(AircraftSpec("c172p"))
    air = Airframe(model)
    assert air.position == air.target == model.trim_deflection
    air.command(40.0)
    assert air.position == pytest.approx(23.0, abs=0.01)
    air.command(-40.0)
    assert air.position == pytest.approx(-28.0, abs=0.01)
    air.advance_to(0.05)
    assert model.truth_extras()["surface"] == pytest.approx(air.position, abs=1e-6)


def test_excitation_flies_the_linear_plant_too_about_its_zero_trim():
    sim, rec = run(LinearFlightModel.from_plant(PLANT), 12, excite=Excitation(0.5, 8.0), seed=4)
    reported = [s.elevator_deg for s in rec.samples]
    assert set(reported[:8]) <= {-0.5, 0.5} and len(set(reported[:8])) == 2 and reported[8] == 0.0
    assert [t["u"][0] for t in rec.truth[:8]] == reported[:8]  # each issued level acted within its interval


def test_prbs_is_seeded_and_its_dwell_is_bounded():
    e = Excitation(1.0, 60.0)
    a, b, c = e.signs(0.05, 1), e.signs(0.05, 1), e.signs(0.05, 2)
    assert a == b and a != c and len(a) == 1200 and set(a) == {-1, 1}
    runs = np.diff(np.flatnonzero(np.diff(a)))
    assert runs.min() >= 4 and runs.max() <= 16  # 0.2 s .. 0.8 s at 20 Hz
    assert abs(np.mean(a)) < 0.15  # balanced about trim
    assert len(e.signs(1.0, 0)) == 60  # h = 1 s: a bit per sample
    assert str(parse_excite_spec("prbs:1:60")) == "prbs:1:60" and parse_excite_spec(None) is None
    for bad in ("prbs:1", "prbs:-1:5", "chirp:1:5", "prbs:a:b", "prbs:1:0"):
        with pytest.raises(UserError, match="bad --excite SPEC"):
            parse_excite_spec(bad)


def test_an_aircraft_vehicle_file_sets_the_aircraft_flags(tmp_path):
    conf = tmp_path / "vehicle.toml"
    conf.write_text(
        'aircraft = "c172p"\nairspeed = 90\naltitude = 4500\nrate = 25\nturbulence = "light"\n'
        'excite = "prbs:2:30"\nfault = "bias:2@100"\n'
    )
    args = parse_args_with_config(build_parser(), ["run", "--config", str(conf), "--rate", "50"])
    settings = settings_from_args(args)
    spec = settings.aircraft
    assert settings.plant is None and spec.name == "c172p" and spec.airspeed_kt == 90.0 and spec.altitude_ft == 4500.0
    assert settings.h == pytest.approx(0.02) and spec.turbulence == "light" and str(settings.excite) == "prbs:2:30"
    assert str(settings.delay) == "uniform:0:0.0092"  # 0.46 h, the contract's share of the sampling period
    plain = settings_from_args(parse_args_with_config(build_parser(), ["run"]))
    assert plain.aircraft is None and plain.plant.name == "paper-continuous" and plain.h == 1.0
    with pytest.raises(UserError, match="--excite and --autopilot"):
        settings_from_args(
            parse_args_with_config(build_parser(), ["run", "--excite", "prbs:1:5", "--autopilot", "-0.5"])
        )
