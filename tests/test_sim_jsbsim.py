"""The JSBSim aircraft (sim_vehicle/jsbsim_model.py), for real: trim, the elevator, faults at the surface,
seeded turbulence, the identification manoeuvre, and the one-line refusals of the CLI. No mocks.

Each flight here is at most 60 simulated seconds of c172p at 20 Hz (a fraction of a second of JSBSim).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.wire.specs import Excitation, parse_delay_spec, parse_fault_spec
from monitor.wire.telemetry import AircraftSample
from sim_vehicle.jsbsim_model import AircraftSpec, JSBSimFlightModel, jsbsim_seed, step_size
from sim_vehicle.simulation import Simulation
from tests.sim_recorder import Recorder

REPO = Path(__file__).resolve().parent.parent
KT = 1852.0 / 3600.0


def c172p(**kw) -> JSBSimFlightModel:
    return JSBSimFlightModel(AircraftSpec("c172p", **kw))


def fly(
    steps: int,
    fault: str | None = None,
    seed: int = 0,
    turbulence: str = "none",
    excite=None,
    delay: str = "const:0.01",
) -> tuple[Simulation, Recorder]:
    """c172p at 20 Hz with nobody commanding: it holds trim (or flies the excitation)."""
    rec = Recorder()
    model = c172p(turbulence=turbulence, seed=seed)
    sim = Simulation(
        None,
        rec,
        steps=steps,
        model=model,
        fault=parse_fault_spec(fault),
        seed=seed,
        delay=parse_delay_spec(delay, seed=seed),
        excite=excite,
    )
    while not sim.done:
        sim.run_until(sim.next_time())
    model.close()
    return sim, rec


def test_c172p_trims_at_100_kt_3000_ft_and_stays_there_open_loop_for_10_s():
    model = c172p()
    assert model.dt == pytest.approx(1 / 120) and model.h == pytest.approx(0.05)
    trim = model.trim
    assert trim["airspeed_kt"] == pytest.approx(100.0, abs=1e-6) and trim["altitude_ft"] == pytest.approx(3000.0)
    assert 2.0 < model.trim_deflection < 8.0  # trailing edge down a few degrees, within the travel
    assert model.travel == pytest.approx((-28.0, 23.0), abs=0.01)  # c172p: -28 deg at -1, +23 deg at +1
    start = model.state()
    assert start[0] == pytest.approx(trim["alpha_deg"]) and start[3] == pytest.approx(100 * KT, abs=1e-6)
    xs = []
    for _ in range(200):  # 10 s, the elevator held at trim
        model.step(0.05, model.trim_deflection, 0.0, [0.0], [])
        xs.append(model.state())
    xs = np.array(xs)
    assert model.t == pytest.approx(10.0) and model.n == 1200
    assert np.abs(xs[:, 0] - start[0]).max() < 0.01  # alpha within 0.01 deg (measured 1e-4)
    assert np.abs(xs[:, 1]).max() < 0.01  # q within 0.01 deg/s (measured 7e-4)
    assert np.abs(xs[:, 2] - start[2]).max() < 0.05 and np.abs(xs[:, 3] - start[3]).max() < 0.05
    assert model.truth_extras()["surface"] == pytest.approx(model.trim_deflection, abs=1e-9)


def test_an_aircraft_jsbsim_s_trim_fails_on_is_trimmed_by_flying_it_and_stays_there_open_loop():
    # pa28 at 100 kt: JSBSim's trim fails ("udot doesn't appear to be trimmable": its engine loop without the
    # magnetos), the autopilot flies it steady at 100 kt and 3000 ft and hands it over, the elevator held there
    model = JSBSimFlightModel(AircraftSpec("pa28", airspeed_kt=100.0))
    assert model.trimmed_by == "flying it on the autopilot"
    trim = model.trim
    assert trim["airspeed_kt"] == pytest.approx(100.0, abs=1.5) and trim["altitude_ft"] == pytest.approx(3000, abs=20)
    assert 0.0 < trim["throttle"] < 1.0 and model.travel[0] < model.trim_deflection < model.travel[1]
    start = model.state()
    xs = []
    for _ in range(200):  # 10 s, the elevator held where the autopilot left it
        model.step(0.05, model.trim_deflection, 0.0, [0.0], [])
        xs.append(model.state())
    xs = np.array(xs)
    # near an equilibrium, not at one (the autopilot's residue: steady within 20 ft/min and 0.1 deg/s)
    assert np.abs(xs[:, 0] - start[0]).max() < 0.3 and np.abs(xs[:, 1]).max() < 0.3  # measured 6e-4 deg, 0.03 deg/s
    assert np.abs(xs[:, 3] - start[3]).max() < 0.5  # m/s
    model.close()


@pytest.mark.parametrize("name, airspeed", [("c172p", 100.0), ("737", 250.0), ("J3Cub", 60.0)])
def test_an_absolute_deflection_reaches_the_surface_and_writing_the_surface_itself_does_not(name, airspeed):
    """Why the command goes through fcs/elevator-cmd-norm: the aircraft's FCS rewrites fcs/elevator-pos-rad
    every step, so a value written there from outside never acts."""
    model = JSBSimFlightModel(AircraftSpec(name, airspeed_kt=airspeed))
    fdm = model.fdm
    assert fdm["fcs/pitch-trim-cmd-norm"] == 0.0  # the trim moved into the command ...
    model.step(0.05, model.trim_deflection, 0.0, [0.0], [])
    assert fdm["fcs/elevator-pos-deg"] == pytest.approx(model.trim_deflection, abs=1e-6)  # ... and the surface stayed
    low, high = model.travel
    for target in (model.trim_deflection + 2.0, model.trim_deflection - 3.0, low + 0.5, high - 0.5):
        model.step(0.05, target, 0.0, [0.0], [])
        assert fdm["fcs/elevator-pos-deg"] == pytest.approx(target, abs=1e-3)
    model.step(0.05, high + 10.0, 0.0, [0.0], [])  # beyond the travel: the surface stops at its end
    assert fdm["fcs/elevator-pos-deg"] == pytest.approx(high, abs=1e-3)
    model.step(0.05, model.trim_deflection, 0.0, [0.0], [])
    fdm["fcs/elevator-pos-rad"] = math.radians(model.trim_deflection + 5.0)
    fdm.run()
    assert fdm["fcs/elevator-pos-deg"] == pytest.approx(model.trim_deflection, abs=1e-3)


def test_a_2_degree_bias_acts_at_the_surface_and_pitches_the_nose_down():
    _, clean = fly(80)
    sim, biased = fly(80, fault="bias:2@20")
    a0 = np.array([t["x"][0] for t in clean.truth])
    a1 = np.array([t["x"][0] for t in biased.truth])
    assert np.array_equal(a0[:21], a1[:21])  # identical until the bias has acted for one interval
    trim = biased.truth[0]["trim"]
    assert all(t["surface"] == pytest.approx(trim, abs=1e-6) for t in biased.truth[:21])
    assert all(t["surface"] == pytest.approx(trim + 2.0, abs=1e-6) for t in biased.truth[21:])
    assert all(t["f"] == [2.0] for t in biased.truth[20:]) and all(t["f"] == [0.0] for t in biased.truth[:20])
    # the servo (what ACTUATOR_OUTPUT_STATUS reports) does not know: the fault is after the actuator
    assert all(s.elevator_deg == pytest.approx(trim) for s in biased.samples)
    # positive elevator is trailing edge down: nose down, alpha falls (c172p: ~0.57 deg/deg after 1 s)
    assert (a1[30:] < a0[30:] - 0.5).all() and a1[40] - a0[40] == pytest.approx(-1.1, abs=0.4)
    q = np.array([t["x"][1] for t in biased.truth])
    assert q[21:26].min() < -1.0  # the pitch rate goes negative first


def test_loss_of_effectiveness_and_stuck_act_on_the_absolute_deflection():
    sim, rec = fly(60, fault="loe:0.5@10-20+stuck:2@30")
    trim = rec.truth[0]["trim"]
    assert [round(t["surface"], 6) for t in rec.truth[10:12]] == [round(trim, 6), round(0.5 * trim, 6)]
    assert rec.truth[25]["surface"] == pytest.approx(trim, abs=1e-6)
    assert all(t["surface"] == pytest.approx(2.0, abs=1e-6) and t["elevator"] == 2.0 for t in rec.truth[31:])


def test_turbulence_is_seeded_same_seed_same_flight_other_seed_other_flight():
    runs = [fly(100, seed=s, turbulence="light")[1].truth for s in (3, 3, 4)]
    assert runs[0] == runs[1]  # every key of every sample, to the bit
    assert [t["x"] for t in runs[0]] != [t["x"] for t in runs[2]]
    assert any(abs(v) > 0.01 for t in runs[0] for v in t["d"])  # the truth's d is JSBSim's turbulence (m/s)
    assert jsbsim_seed(0) != jsbsim_seed(1) and jsbsim_seed(2**31 - 2) == jsbsim_seed(0)


def test_moderate_turbulence_shakes_alpha_more_than_light():
    def alpha_std(level: str) -> float:
        return float(np.std([t["x"][0] for t in fly(600, seed=5, turbulence=level)[1].truth]))

    none, light, moderate = alpha_std("none"), alpha_std("light"), alpha_std("moderate")
    assert none < 0.01 < light < moderate and moderate > 1.2 * light


def test_excitation_is_a_prbs_of_the_right_amplitude_about_trim_then_trim():
    h, excite = 0.05, Excitation(amplitude=1.5, seconds=5.0)
    sim, rec = fly(160, excite=excite, seed=2)
    trim = rec.truth[0]["trim"]
    reported = np.array([s.elevator_deg for s in rec.samples])
    levels = np.round(reported[:100] - trim, 9)
    assert set(levels) == {-1.5, 1.5}
    switches = np.flatnonzero(np.diff(levels)) + 1
    dwell = np.diff(np.concatenate([[0], switches]))
    assert dwell.min() >= round(0.2 / h) and dwell.max() <= round(0.8 / h)  # 0.2-0.8 s between switches
    assert len(switches) >= 6
    assert reported[100] == pytest.approx(trim) and np.allclose(reported[101:], trim)  # back to trim and held
    # what was issued acted on the surface after its drawn delay (const 0.01 s here): by the next sample
    surface = np.array([t["surface"] for t in rec.truth])
    assert np.allclose(surface[1:101], reported[:100], atol=1e-6)
    assert sim.stats.samples["onboard"] == 101 and sim.stats.commands["applied"] == 0  # flown on board
    # outside commands are counted and ignored during the manoeuvre, followed after it
    assert sim.receive_command(50, 0.0, sim.airframe.t) == "ignored_excitation"
    assert sim.stats.commands["ignored_excitation"] == 1
    assert np.std([t["x"][0] for t in rec.truth[:100]]) > 0.2  # it excites the short period


def test_samples_carry_theta_airspeed_and_the_attitude():
    sim, rec = fly(3)
    s = rec.samples[0]
    assert isinstance(s, AircraftSample)
    assert s.theta_deg == pytest.approx(rec.truth[0]["x"][2]) and s.airspeed_m_s == pytest.approx(100 * KT, abs=1e-6)
    groundspeed, heading, throttle, alt, climb = s.hud
    assert alt == pytest.approx(914.4, abs=0.01) and 0 < throttle <= 100 and abs(climb) < 0.01
    assert rec.truth[0]["states"] == ["alpha_deg", "q_deg_s", "theta_deg", "airspeed_m_s"]


def test_own_aircraft_from_a_directory_of_aircraft_or_its_own_folder(tmp_path):
    import jsbsim

    bundled = Path(jsbsim.get_default_root_dir()) / "aircraft" / "c172p"
    (tmp_path / "fleet").mkdir()
    (tmp_path / "fleet" / "c172p").symlink_to(bundled, target_is_directory=True)
    a = JSBSimFlightModel(AircraftSpec("c172p", aircraft_dir=str(tmp_path / "fleet")))
    b = JSBSimFlightModel(AircraftSpec("c172p", aircraft_dir=str(tmp_path / "fleet" / "c172p")))
    assert a.trim_deflection == pytest.approx(b.trim_deflection) == pytest.approx(c172p().trim_deflection)
    with pytest.raises(UserError, match="no c172x.xml in --aircraft-dir"):
        JSBSimFlightModel(AircraftSpec("c172x", aircraft_dir=str(tmp_path / "fleet")))


def test_step_size_divides_the_sampling_period():
    assert step_size(0.05) == pytest.approx(1 / 120)
    assert step_size(0.02) == pytest.approx(0.02 / 3)  # 50 Hz: 150 Hz steps, not 120
    assert step_size(1.0) == pytest.approx(1 / 120)


def _cli(*args: str) -> subprocess.CompletedProcess:
    # stdout a pipe and block-buffered, as under a service manager or CI: with PYTHONUNBUFFERED set (many
    # developers' shells) a message printed at the wrong moment reaches the pipe at once and a leak at exit hides
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    return subprocess.run(
        [sys.executable, "-m", "sim_vehicle", "run", "--no-zenoh", "--steps", "5", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
        env=env,
    )


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--aircraft", "c172p", "--airspeed", "300"],
            "--aircraft c172p does not trim at 300 kt, 3000 ft: JSBSim's trim failed "
            "(Trim Failed (Sorry, udot doesn't appear to be trimmable)); flown by the autopilot it cannot hold 300 kt: "
            "throttle at full",
        ),
        (["--aircraft", "no-such-plane"], "--aircraft no-such-plane: JSBSim has no such aircraft"),
        (["--aircraft", "c172p", "--wind", "paper"], "--wind does not go with --aircraft"),
        (["--airspeed", "90"], "--airspeed goes with --aircraft NAME"),
    ],
)
def test_an_aircraft_that_cannot_fly_is_one_line_and_exit_2(args, message):
    proc = _cli(*args)
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""  # nothing JSBSim printed leaks to stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sim-vehicle run: error: ") and message in lines[0], proc.stderr


def test_sim_vehicle_import_help_and_version_do_not_load_jsbsim():
    code = (
        "import sys, sim_vehicle, sim_vehicle.cli, sim_vehicle.simulation, sim_vehicle.config;"
        "sim_vehicle.cli.build_parser().format_help(); print('jsbsim' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert out.stdout.strip() == "False", out.stderr
    version = subprocess.run(
        [sys.executable, "-m", "sim_vehicle", "--version"], capture_output=True, text=True, timeout=60, cwd=REPO
    )
    assert version.returncode == 0 and version.stdout.startswith("sim-vehicle 0.") and "JSBSim 1.3" in version.stdout
