"""``fault-monitor identify``: a c172p flown by JSBSim itself, logged as MAVProxy logs, identified, cross-checked.

The flight and its log (``tests/c172p_flights.py``): c172p trimmed by JSBSim at 100 kt, 3000 ft; 5 s of trimmed
flight, then an elevator PRBS of +-1 deg for 60 s, integrated at 120 Hz, sampled at 20 Hz (h = 0.05 s) and written
as MAVProxy writes a tlog. No mocks: the log goes through the command, the link layer and the maths as a user's
would.

The cross-check is JSBSim's own linearisation (``jsbsim.FGLinearization``) at the same trim, converted to the
plant's units (Alpha, Theta rad -> deg; Q rad/s -> deg/s; Vt ft/s; DeCmd per unit command -> per degree of
``fcs/elevator-pos-deg``, the scale read from JSBSim at the trim).

The flight is integrated by Adams-Bashforth 2, not JSBSim's default forward Euler, so that it can be compared
with the continuous linearisation (why: ``tests/c172p_flights.py``).
"""

from __future__ import annotations

import json
import math
import time
import tomllib
from pathlib import Path

import jsbsim
import numpy as np
import pytest

from monitor.model.identification import FlightData, identify, modes_of, nrmse_fit
from monitor.model.plant import load_plant, parse_plant
from tests.c172p_flights import Flight, H, fly, quiet, trimmed_c172p, write_tlog

FT_TO_M = 0.3048
R2D = 180.0 / math.pi


def linearisation(airspeed_kt: float = 100.0, altitude_ft: float = 3000.0) -> dict:
    """JSBSim's own linearisation at the trim, in the plant's units: A (alpha, q, theta, airspeed), B per degree."""
    fdm = trimmed_c172p(airspeed_kt, altitude_ft)
    with quiet():
        lin = jsbsim.FGLinearization(fdm)
    names, inputs = list(lin.x_names), list(lin.u_names)
    A, B = np.array(lin.system_matrix), np.array(lin.input_matrix)
    order = [names.index(s) for s in ("Alpha", "Q", "Theta", "Vt")]
    # to deg, deg/s, deg, and m/s (Vt is true airspeed in ft/s; VFR_HUD carries calibrated airspeed: the
    # linearisation's airspeed row is compared for information only)
    S = np.diag([R2D, R2D, R2D, FT_TO_M])
    A4 = S @ A[np.ix_(order, order)] @ np.linalg.inv(S)
    # the elevator: degrees of fcs/elevator-pos-deg per unit of DeCmd (fcs/elevator-cmd-norm), read at the trim
    total = fdm["fcs/elevator-cmd-norm"] + fdm["fcs/pitch-trim-cmd-norm"]
    fdm.suspend_integration()
    fdm["fcs/pitch-trim-cmd-norm"] = 0.0
    deg = []
    for command in (total - 0.01, total + 0.01):
        fdm["fcs/elevator-cmd-norm"] = command
        fdm.run()
        deg.append(fdm["fcs/elevator-pos-deg"])
    deg_per_command = (deg[1] - deg[0]) / 0.02
    B4 = S @ B[order, inputs.index("DeCmd")][:, None] / deg_per_command
    return {
        "A": A4,
        "B": B4,
        "deg_per_command": deg_per_command,
        "modes": modes_of(A4),
        "short_period": modes_of(A4[:2, :2])[0],
    }


@pytest.fixture(scope="session")
def c172p_flight(tmp_path_factory) -> dict:
    """The flight (generated once), its tlog and JSBSim's linearisation."""
    t = time.perf_counter()
    flight = fly()
    work = tmp_path_factory.mktemp("identify")
    log = work / "c172p.tlog"
    write_tlog(log, flight)
    lin = linearisation()
    return {"flight": flight, "log": log, "lin": lin, "work": work, "seconds": time.perf_counter() - t}


def _identify(*argv: str) -> tuple[int, str, str]:
    """``fault-monitor identify ...`` in process (the e2e test runs the installed command)."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from monitor.cli import main

    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(["identify", *argv])
    return code, out.getvalue(), err.getvalue()


def test_c172p_identified_from_its_log_fits_held_out_data_and_matches_jsbsim_linearisation(c172p_flight) -> None:
    out = c172p_flight["work"] / "c172p.toml"
    code, stdout, stderr = _identify(str(c172p_flight["log"]), "--out", str(out), "--json")
    assert code == 0, stderr
    report = json.loads(stdout)
    fit = report["fit_percent"]
    print("held-out fit %:", {k: round(v, 1) for k, v in fit.items()})
    assert fit["alpha"] >= 90.0 and fit["q"] >= 90.0
    assert fit["theta"] >= 80.0 and fit["airspeed"] >= 80.0  # measured 93 / 94 %
    assert report["h"] == pytest.approx(H)
    assert report["samples"]["log"] == 1300
    assert report["samples"]["validation"] == 360  # the last 30 % of the 60 s manoeuvre
    assert report["excitation"]["lead_in_s"] == pytest.approx(5.0)
    inventory = report["log"]["inventory"]  # what the log holds: 5 messages a sample + a HEARTBEAT a second
    assert (
        inventory["frames_v2"] == 1300 * 4 + 65 and inventory["frames_v1"] == 0 and inventory["sysids"] == {"1": 5265}
    )
    assert {m["name"]: m["hz"] for m in inventory["messages"]}["AOA_SSA"] == pytest.approx(20.0, rel=0.01)

    lin = c172p_flight["lin"]
    sp_lin, ph_lin = lin["modes"]
    sp, ph = (next(m for m in report["modes"] if m["name"] == name) for name in ("short period", "phugoid"))
    print(
        f"short period: identified wn {sp['wn_rad_s']:.3f} zeta {sp['zeta']:.3f}; "
        f"FGLinearization wn {sp_lin.wn:.3f} zeta {sp_lin.zeta:.3f}"
    )
    print(
        f"phugoid: identified wn {ph['wn_rad_s']:.4f} zeta {ph['zeta']:.3f} period {ph['period_s']:.1f} s; "
        f"FGLinearization wn {ph_lin.wn:.4f} zeta {ph_lin.zeta:.3f} period {ph_lin.period_s:.1f} s"
    )
    assert sp["wn_rad_s"] == pytest.approx(sp_lin.wn, rel=0.10)
    assert sp["zeta"] == pytest.approx(sp_lin.zeta, rel=0.10)
    assert ph["period_s"] == pytest.approx(ph_lin.period_s, rel=0.15)  # measured 5 % apart
    # the elevator's effect on q (M_de), the largest entry of B, in the plant's units
    B = np.array(report["B_c"])
    print(f"B_c q row: identified {B[1, 0]:.3f}, linearised {lin['B'][1, 0]:.3f} deg/s^2 per deg")
    assert B[1, 0] == pytest.approx(lin["B"][1, 0], rel=0.15)

    # the operating point is the trim the flight started from
    op = report["operating_point"]
    flight = c172p_flight["flight"]
    assert op["elevator"] == pytest.approx(flight.trim_elevator, abs=1e-4)
    assert op["alpha"] == pytest.approx(flight.alpha[0], abs=0.01)
    assert op["airspeed"] == pytest.approx(flight.airspeed[0], abs=0.01)

    # the file: loads as it is, its [identification] and [signals] tables as specified
    plant = load_plant(out)
    raw = tomllib.loads(out.read_text())
    assert plant.form == "continuous" and plant.n == 4 and plant.unit == "deg"
    assert plant.h == pytest.approx(H) and plant.tau_min == 0 and plant.tau_max == pytest.approx(0.46 * H)
    assert np.allclose(plant.continuous.D_cf, plant.continuous.B_c)
    assert np.allclose(plant.continuous.D_cd[:, 0], plant.continuous.A_c[:, 0])
    assert np.array_equal(plant.C, np.eye(4)) and plant.actuator.limit == 25.0
    sig = raw["signals"]
    assert sig["outputs"] == ["alpha", "q", "theta", "airspeed"] and sig["actuator"] == ["elevator"]
    assert set(sig["operating_point"]) == {"alpha", "q", "theta", "airspeed", "elevator"}
    assert sig["measured"]["airspeed"] == {"field": "VFR_HUD.airspeed", "unit": "m/s"}
    assert sig["command"] == {
        "message": "SET_ACTUATOR_CONTROL_TARGET",
        "channels": [1],
        "full_scale": [30.0],
        "group": 0,
    }
    ident = raw["identification"]
    assert ident["fit_percent"]["q"] == pytest.approx(fit["q"], abs=0.01)
    assert [m["name"] for m in ident["modes"]] == ["short period", "phugoid"]


def test_short_period_model_from_the_same_log(c172p_flight) -> None:
    out = c172p_flight["work"] / "sp.toml"
    code, stdout, stderr = _identify(str(c172p_flight["log"]), "--model", "short-period", "--out", str(out))
    assert code == 0, stderr
    print(stdout)
    plant = load_plant(out)
    assert plant.n == 2 and tomllib.loads(out.read_text())["signals"]["outputs"] == ["alpha", "q"]
    # airspeed is no state of this model: it is recorded, and its mean over the log is the flight condition (an
    # envelope of short-period points is scheduled on it)
    signals = tomllib.loads(out.read_text())["signals"]
    assert "airspeed" in signals["measured"] and "airspeed" not in signals["operating_point"]
    assert signals["condition"]["airspeed"] == pytest.approx(51.4, abs=1.0)
    assert signals["condition"]["roll"] == pytest.approx(0.0, abs=1.0)  # wings level: where the log was flown
    sp = modes_of(plant.continuous.A_c)[0]
    sp_lin = c172p_flight["lin"]["short_period"]
    assert sp.wn == pytest.approx(sp_lin.wn, rel=0.10) and sp.zeta == pytest.approx(sp_lin.zeta, rel=0.10)
    assert "alpha" in stdout and "fit on held-out data" in stdout
    assert "log holds: 5265 records over 65.0 s, 5265 frames (MAVLink 1: 0, MAVLink 2: 5265)" in stdout


def test_validation_is_a_free_run_not_a_one_step_prediction(c172p_flight) -> None:
    """The score is the free run's over the held-out samples; predicting one step from each measured state scores
    higher on the same samples, which is why it is not the measure."""
    flight = c172p_flight["flight"]
    X = np.column_stack([flight.alpha, flight.q * R2D, flight.theta * R2D, flight.airspeed])
    data = FlightData(H, np.arange(len(X)), X, flight.elevator[:, None], ("alpha", "q", "theta", "airspeed"))
    result = identify(data)
    run = result.validation_run
    assert np.allclose(nrmse_fit(run["y"], run["y_hat"]), list(result.fit_validation.values()))
    # one step from every measured state is far better than the free run: the score is the free run's
    one_step = (
        result.A_d @ run["y"][:-1].T
        + result.B_d @ (flight.elevator[-len(run["y"]) : -1][None, :] - result.operating_point["elevator"])
    ).T
    assert np.all(nrmse_fit(run["y"][1:], one_step) > np.array(list(result.fit_validation.values())))


def test_sensor_noise_does_not_bias_the_modes(c172p_flight) -> None:
    """White noise on every sensor (alpha 0.05 deg, q 0.2 deg/s, theta 0.05 deg, airspeed 0.1 m/s rms): equation-
    error least squares alone is biased by it (measured: phugoid zeta 1.35, no oscillation, theta fit 8 %); the
    output-error refinement, which fits the free run, is not."""
    flight = c172p_flight["flight"]
    X = np.column_stack([flight.alpha, flight.q * R2D, flight.theta * R2D, flight.airspeed])
    X = X + np.random.default_rng(1).normal(size=X.shape) * [0.05, 0.2, 0.05, 0.1]
    result = identify(
        FlightData(H, np.arange(len(X)), X, flight.elevator[:, None], ("alpha", "q", "theta", "airspeed"))
    )
    assert result.method["refined"] and result.method["cost"] < result.method["cost_least_squares"]
    sp, ph = result.modes
    sp_lin, ph_lin = c172p_flight["lin"]["modes"]
    print(f"with noise: {sp.describe()}; {ph.describe()}; fit {result.fit_validation}")
    assert sp.wn == pytest.approx(sp_lin.wn, rel=0.10) and sp.zeta == pytest.approx(sp_lin.zeta, rel=0.10)
    assert ph.oscillatory and ph.period_s == pytest.approx(ph_lin.period_s, rel=0.15)
    assert min(result.fit_validation.values()) > 85  # against noisy measurements


def test_a_flight_that_starts_with_the_manoeuvre_takes_the_models_equilibrium_as_trim() -> None:
    """sim-vehicle --excite starts the PRBS at once and returns to trim after it: no lead-in to measure."""
    flight = fly(seconds=40.0, lead_in=0.0, tail=10.0, seed=3)
    X = np.column_stack([flight.alpha, flight.q * R2D, flight.theta * R2D, flight.airspeed])
    result = identify(
        FlightData(H, np.arange(len(X)), X, flight.elevator[:, None], ("alpha", "q", "theta", "airspeed"))
    )
    op = result.operating_point
    assert "equilibrium" in result.operating_point_source
    assert op["elevator"] == pytest.approx(flight.trim_elevator, abs=1e-6)
    assert op["alpha"] == pytest.approx(flight.alpha[0], abs=0.02)
    assert op["theta"] == pytest.approx(flight.theta[0] * R2D, abs=0.1)
    assert op["airspeed"] == pytest.approx(flight.airspeed[0], abs=0.1)
    assert result.fit_validation["alpha"] >= 90 and result.fit_validation["q"] >= 90


def test_a_trim_only_log_is_no_excitation(tmp_path: Path) -> None:
    flight = fly(seconds=0.0, lead_in=20.0)
    log = tmp_path / "trim.tlog"
    write_tlog(log, flight)
    code, stdout, stderr = _identify(str(log), "--out", str(tmp_path / "p.toml"))
    assert code == 2 and stdout == ""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "error: no excitation" in lines[0], stderr
    assert not (tmp_path / "p.toml").exists()


def test_a_log_without_vfr_hud_names_the_missing_signal(c172p_flight, tmp_path: Path) -> None:
    log = tmp_path / "nohud.tlog"
    write_tlog(log, c172p_flight["flight"], hud=False)
    code, _out, stderr = _identify(str(log), "--out", str(tmp_path / "p.toml"))
    lines = stderr.strip().splitlines()
    assert code == 2 and len(lines) == 1, stderr
    assert "missing signals: airspeed (VFR_HUD.airspeed)" in lines[0] and "--model short-period" in lines[0]
    code, _out, stderr = _identify(str(log), "--out", str(tmp_path / "p.toml"), "--model", "short-period")
    assert code == 0, stderr


def test_a_too_short_log_is_refused(c172p_flight, tmp_path: Path) -> None:
    full = c172p_flight["flight"]
    short = Flight(
        *(getattr(full, f)[: 100 + 80] for f in ("alpha", "q", "theta", "airspeed", "elevator")),
        trim_elevator=full.trim_elevator,
    )  # 5 s of trim + 4 s of manoeuvre
    log = tmp_path / "short.tlog"
    write_tlog(log, short)
    code, _out, stderr = _identify(str(log), "--out", str(tmp_path / "p.toml"))
    lines = stderr.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "error: too short: the excitation lasts 4.0 s" in lines[0], stderr
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    code, _out, stderr = _identify(str(empty), "--out", str(tmp_path / "p.toml"))
    assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr


def test_sysid_h_and_tau_max_options(c172p_flight, tmp_path: Path) -> None:
    out = tmp_path / "p.toml"
    code, stdout, stderr = _identify(
        str(c172p_flight["log"]),
        "--out",
        str(out),
        "--h",
        "0.1",
        "--tau-max",
        "0.04",
        "--sysid",
        "1",
        "--json",
        "--model",
        "short-period",
    )
    assert code == 0, stderr
    report = json.loads(stdout)
    plant = load_plant(out)
    assert plant.h == pytest.approx(0.1) and plant.tau_max == pytest.approx(0.04)
    assert report["samples"]["log"] == 650 and report["fit_percent"]["alpha"] > 90
    for argv, words in (
        (("--h", "0.07"), "whole multiple"),
        (("--tau-min", "0.2", "--tau-max", "0.1"), "tau_min <= tau_max"),
        (("--tau-max", "0.5"), "at most 3"),
        (("--sysid", "2"), "missing signals"),
    ):
        code, _o, stderr = _identify(str(c172p_flight["log"]), "--out", str(out), *argv)
        assert code == 2 and words in stderr and len(stderr.strip().splitlines()) == 1, stderr


def test_lost_records_several_vehicles_and_a_signal_map_file(c172p_flight, tmp_path: Path) -> None:
    """5 % of the records lost on the way (a sample missing a part is dropped, the rest are identified); two
    vehicles in one log (--sysid chooses); the plant file written is itself a --signals FILE."""
    log = tmp_path / "lossy.tlog"
    write_tlog(log, c172p_flight["flight"], drop=0.05)
    out = tmp_path / "lossy.toml"
    code, stdout, stderr = _identify(str(log), "--out", str(out), "--json")
    assert code == 0, stderr
    report = json.loads(stdout)
    assert 1000 < report["samples"]["log"] < 1300  # ~15 % of samples lose one of their 4 records
    # measured: alpha 89.9, q 88.1, theta 82.8, airspeed 93.2 %: a lost sample's elevator is a guess (the
    # midpoint of its neighbours), which the free run integrates; the modes hardly move
    assert min(report["fit_percent"].values()) >= 75
    sp = report["modes"][0]
    assert sp["wn_rad_s"] == pytest.approx(c172p_flight["lin"]["short_period"].wn, rel=0.10)
    assert sp["zeta"] == pytest.approx(c172p_flight["lin"]["short_period"].zeta, rel=0.10)

    write_tlog(log, c172p_flight["flight"], sysid=2, append=True)
    code, _out, stderr = _identify(str(log), "--out", str(out))
    assert code == 2 and "vehicles 1, 2: choose one with --sysid" in stderr
    reference = tmp_path / "reference.toml"  # made here: under xdist the test that writes work/c172p.toml may
    assert _identify(str(c172p_flight["log"]), "--out", str(reference))[0] == 0  # run on the other worker
    code, stdout, stderr = _identify(str(log), "--out", str(out), "--sysid", "2", "--json", "--signals", str(reference))
    assert code == 0, stderr
    assert json.loads(stdout)["samples"]["log"] == 1300 and json.loads(stdout)["sysid"] == 2


def test_plant_file_identification_table_is_information_only() -> None:
    base = load_plant("paper-continuous").raw
    text = "\n".join(f"{k} = {json.dumps(v)}" for k, v in base.items() if not isinstance(v, dict))
    plain = parse_plant(text + "\n[actuator]\nlimit = 30.0\n")
    info = parse_plant(
        text + '\n[actuator]\nlimit = 30.0\n[identification]\nsource_log = "x.tlog"\nfit_percent = { alpha = 97.0 }\n'
    )
    assert info.digest == plain.digest  # not part of the dynamics: gains stay valid
    assert np.array_equal(info.A, plain.A)
    with pytest.raises(Exception, match="'identification' must be a table"):
        parse_plant(text + "\nidentification = 3\n[actuator]\nlimit = 30.0\n")


def test_the_gust_is_read_from_the_one_step_residual_along_the_gust_direction() -> None:
    """A known 2-state model driven by a Gauss-Markov gust through its alpha column: sigma and time constant back."""
    from scipy.linalg import expm

    from monitor.model.identification import gust_from_residual

    h, T, sigma = 0.05, 0.4, 0.7
    A_c = np.array([[-2.0, 1.0], [-20.0, -4.0]])
    A_d = expm(A_c * h)
    B_d = np.array([[0.01], [-1.2]])
    Dd = (A_d - np.eye(2))[:, [0]]
    rng = np.random.default_rng(5)
    a, n = np.exp(-h / T), 40_000
    d = np.zeros(n)
    for k in range(1, n):
        d[k] = a * d[k - 1] + sigma * np.sqrt(1 - a * a) * rng.normal()
    u = np.sign(rng.normal(size=(n, 1)))
    x = np.zeros((n, 2))
    for k in range(n - 1):
        x[k + 1] = A_d @ x[k] + B_d @ u[k] + Dd[:, 0] * d[k]
    gust = gust_from_residual(np.arange(n), x, u, A_d, B_d, ("alpha", "q"), h)
    assert gust is not None and abs(gust["sigma"] - sigma) < 0.05 * sigma, gust
    expected = h * (0.5 + a / (1 - a))  # the integral time scale of the sampled process (~T for h << T)
    assert abs(gust["time_constant"] - expected) < 0.2 * expected, gust


def test_air_only_keeps_the_model_and_measures_the_gust_of_another_log(c172p_flight, tmp_path: Path) -> None:
    """On the very log it was identified from, --air-only measures the same gust identify wrote (same model, same
    operating point); the model, the map and every other table stay the plant's; the level is written."""
    plant_path, kept_path = tmp_path / "p.toml", tmp_path / "kept.toml"
    code, _out, stderr = _identify(str(c172p_flight["log"]), "--out", str(plant_path))
    assert code == 0, stderr
    code, out, stderr = _identify(
        str(c172p_flight["log"]), "--air-only", str(plant_path), "--turbulence", "light", "--out", str(kept_path)
    )
    assert code == 0 and "measured the air" in out, stderr
    plant, kept = load_plant(plant_path), load_plant(kept_path)
    assert np.array_equal(plant.A, kept.A) and plant.signals == kept.signals and plant.digest != kept.digest
    assert kept.disturbance.turbulence == "light"
    assert kept.disturbance.sigma == pytest.approx(plant.disturbance.sigma, rel=1e-3)
    assert kept.disturbance.time_constant == pytest.approx(plant.disturbance.time_constant, rel=1e-3)
    code, _o, stderr = _identify(
        str(c172p_flight["log"]), "--air-only", str(tmp_path / "none.toml"), "--out", str(tmp_path / "x.toml")
    )
    assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr


def test_a_window_identifies_one_leg_of_the_log(c172p_flight, tmp_path: Path) -> None:
    """--window START:END: the samples from START to END s after the first one (a mission's identification leg)."""
    log = str(c172p_flight["log"])
    whole, leg, wide = tmp_path / "whole.toml", tmp_path / "leg.toml", tmp_path / "wide.toml"
    assert _identify(log, "--out", str(whole))[0] == 0
    assert _identify(log, "--out", str(wide), "--window", "0:1000")[0] == 0
    code, _out, stderr = _identify(log, "--out", str(leg), "--window", "0:40", "--json")
    assert code == 0, stderr
    a_whole, a_wide, a_leg = (np.array(load_plant(str(p)).raw["A_c"]) for p in (whole, wide, leg))
    assert np.array_equal(a_whole, a_wide)  # a window past both ends is the whole log
    assert not np.allclose(a_whole, a_leg)  # the leg was fitted on its own samples: another estimate
    n_leg = json.loads(_out)["samples"]["log"]
    assert n_leg == 800  # 40 s at 20 Hz of a 65 s log
    assert json.loads(_identify(log, "--out", str(whole), "--json")[1])["samples"]["log"] == 1300


@pytest.mark.parametrize(
    "window, message",
    [
        ("0:4", "no excitation"),  # the quiet lead-in alone
        ("500:600", "--window 500:600 s holds no sample of sysid 1 (its samples span 0-"),
        ("5:3", "--window START:END needs 0 <= START < END seconds, got 5:3"),
    ],
)
def test_a_window_without_a_leg_is_one_line(c172p_flight, tmp_path: Path, window: str, message: str) -> None:
    code, stdout, stderr = _identify(str(c172p_flight["log"]), "--out", str(tmp_path / "p.toml"), "--window", window)
    lines = stderr.strip().splitlines()
    assert code == 2 and stdout == "" and len(lines) == 1 and message in lines[0], stderr
    assert not (tmp_path / "p.toml").exists()


def test_a_known_input_that_does_not_move_or_is_a_state_is_one_line(c172p_flight) -> None:
    out = c172p_flight["work"] / "known.toml"
    code, _stdout, stderr = _identify(str(c172p_flight["log"]), "--known-input", "throttle", "--out", str(out))
    assert code == 2 and "--known-input throttle: it does not move over the log" in stderr
    assert stderr.count("\n") == 1 and not out.exists()
    code, _stdout, stderr = _identify(str(c172p_flight["log"]), "--known-input", "q", "--out", str(out))
    assert code == 2 and "--known-input q: it is a state or the actuator of the model" in stderr


def test_air_only_on_an_envelope_measures_with_the_nearest_point_and_scales_every_point_by_airspeed(
    c172p_flight, tmp_path: Path
) -> None:
    """``--air-only ENV.toml``: the gust is measured once, with the point nearest where the log flew (the same
    figure as that point's own plant gives), and carried to every point as ``sigma V_m / V`` and ``T V_m / V``
    (a vertical gust seen as an angle of attack, and its length over the speed). A log that moves the schedule
    over a large share of the points' span is refused in one line."""
    import re

    from monitor.model.envelope import load_envelope

    log = str(c172p_flight["log"])
    cruise = tmp_path / "cruise.toml"
    assert _identify(log, "--out", str(cruise))[0] == 0
    v_cruise = load_plant(cruise).signals["operating_point"]["airspeed"]

    def moved(name: str, speed: float) -> Path:  # the same model placed at another airspeed
        text = re.sub(r"airspeed = [0-9.eE+-]+", f"airspeed = {speed!r}", cruise.read_text("utf-8"), count=1)
        path = tmp_path / f"{name}.toml"
        path.write_text(text, "utf-8")
        return path

    for name, slow in (("wide", 0.7 * v_cruise), ("narrow", v_cruise - 0.05)):
        env = tmp_path / f"{name}-env.toml"
        code = main_cli(
            "envelope", str(cruise), str(moved(f"{name}-slow", slow)), "--schedule", "airspeed", "--out", str(env)
        )
        assert code == 0
        out = tmp_path / f"{name}-air.toml"
        code, stdout, stderr = _identify(log, "--air-only", str(env), "--turbulence", "light", "--out", str(out))
        if name == "narrow":  # the flight's own speed changes cover the points' 0.05 m/s many times over
            assert code == 2 and "--window" in stderr and len(stderr.strip().splitlines()) == 1, stderr
            assert not out.exists()
            continue
        assert code == 0 and "with point cruise" in stdout, stderr
    kept = tmp_path / "kept.toml"
    assert _identify(log, "--air-only", str(cruise), "--out", str(kept))[0] == 0
    single = load_plant(kept).disturbance
    points = {p.name: p.plant for p in load_envelope(tmp_path / "wide-air.toml").points}
    fast, slow_point = points["cruise"].disturbance, points["wide-slow"].disturbance
    assert fast.turbulence == slow_point.turbulence == "light"
    # the cruise point's model is the single plant's: the same residual, scaled by the log's mean speed over its
    # trim speed (the flight holds about its trim)
    assert fast.sigma == pytest.approx(single.sigma, rel=0.02)
    assert fast.time_constant == pytest.approx(single.time_constant, rel=0.02)
    assert slow_point.sigma / fast.sigma == pytest.approx(1 / 0.7, rel=1e-4)
    assert slow_point.time_constant / fast.time_constant == pytest.approx(1 / 0.7, rel=1e-4)
    # the model and the place of each point are kept
    assert np.array_equal(points["cruise"].A, load_plant(cruise).A)


def main_cli(*argv: str) -> int:
    from monitor.cli import main

    return main(list(argv))
