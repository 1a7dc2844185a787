"""Derived signals (``monitor/link/derived.py``) against the quantity computed independently: JSBSim's own α, β
and true airspeed, for a c172p flown in process in a steady crosswind and light turbulence (a few seconds),
derived from its NED velocity, attitude and wind as an autopilot without a vane reports them; through the link
pipeline that ``run --observe`` uses (a tlog of MAVLink messages), and through a PX4 ULog log.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.link.derived import parse_derivation
from monitor.link.signals import parse_signals
from tests.derived_maps import MAVLINK_MAP
from tests.px4_flight import T0_US, H, fly, quaternion, write_mavlink_tlog, write_px4_ulog

PX4_MAP = """
[signals]
instant = "vehicle_angular_velocity"
outputs = ["alpha"]
actuator = ["elevator"]
[signals.measured]
q = { derive = "degrees", input = "vehicle_angular_velocity.xyz[1]" }
elevator = { derive = "control", input = "actuator_servos.control[1]", throw = [-28.0, 23.0], unit = "deg" }
[signals.measured.alpha]
derive = "angle_of_attack"
velocity_ned = ["vehicle_local_position.vx", "vehicle_local_position.vy", "vehicle_local_position.vz"]
attitude_quaternion = [
    "vehicle_attitude.q[0]", "vehicle_attitude.q[1]", "vehicle_attitude.q[2]", "vehicle_attitude.q[3]"
]
wind_ne = [{ field = "wind.windspeed_north", hold = 1.5 }, { field = "wind.windspeed_east", hold = 1.5 }]
[signals.measured.elevator_pwm]
derive = "pwm"
input = { field = "actuator_outputs.output[1]", hold = 0.2 }
pwm = [1000, 1500, 2000]
throw = [-28.0, 23.0]
"""


@pytest.fixture(scope="module")
def windy():
    """4 s of c172p at 90 kt: a 15 fps north, -20 fps east wind set after the trim (it weathervanes: beta swings
    +-5 deg), light MIL-spec turbulence, an elevator PRBS of +-1 deg after 1 s."""
    return fly(4.0, lead_in=1.0, wind_ned_fps=(15.0, -20.0, 0.0), turbulence="light")


@pytest.fixture(scope="module")
def steady():
    """The same in a steady wind without turbulence: what PX4's 1 Hz horizontal wind estimate can describe."""
    return fly(4.0, lead_in=1.0, wind_ned_fps=(15.0, -20.0, 0.0))


def _derivation(spec: dict):
    return parse_derivation("x", spec, "test", lambda _name, _ref, _where: None)[0]


def _values(derivation, groups) -> dict[str, float]:
    return {
        n: float(v)
        for (_role, names), g in zip(derivation.roles, groups, strict=True)
        for n, v in zip(names, g, strict=True)
    }


def test_alpha_beta_and_airspeed_derived_equal_jsbsim_s_own(windy) -> None:
    f = windy
    ned = {"velocity_ned": ["a"] * 3, "wind_ned": ["a"] * 3}
    alpha_q = _derivation({"derive": "angle_of_attack", **ned, "attitude_quaternion": ["a"] * 4})
    alpha_e = _derivation({"derive": "angle_of_attack", **ned, "attitude_euler": ["a"] * 3, "unit": "rad"})
    beta = _derivation({"derive": "sideslip", **ned, "attitude_euler": ["a"] * 3})
    tas = _derivation({"derive": "airspeed", **ned})
    err = np.zeros((len(f), 5))
    for k in range(len(f)):
        v, e, w = f.v_ned[k], f.euler[k], f.wind[k]
        a = alpha_q.compute(_values(alpha_q, [v, quaternion(*e), w]))
        b = beta.compute(_values(beta, [v, e, w]))
        speed = tas.compute(_values(tas, [v, w]))
        err[k] = (
            a - f.alpha[k],
            math.degrees(alpha_e.compute(_values(alpha_e, [v, e, w]))) - f.alpha[k],
            b - f.beta[k],
            speed - f.tas[k],
            speed * math.cos(math.radians(a)) * math.cos(math.radians(b)) - f.u_aero[k],  # velocities/u-aero-fps
        )
    assert np.max(np.abs(err)) < 1e-6, np.max(np.abs(err), axis=0)
    for i, angle in enumerate(("roll", "pitch", "yaw")):  # JSBSim's attitude/phi-rad, theta-rad, psi-rad
        d = _derivation({"derive": angle, "attitude_quaternion": ["a"] * 4, "unit": "rad"})
        got = [d.compute(_values(d, [quaternion(*f.euler[k])])) for k in range(len(f))]
        assert np.allclose(np.unwrap(got), np.unwrap(f.euler[:, i]), atol=1e-9), angle
    assert np.ptp(f.alpha) > 2.0 and np.ptp(f.beta) > 5.0  # a flight that moves them
    no_wind = _derivation({"derive": "angle_of_attack", "velocity_ned": ["a"] * 3, "attitude_euler": ["a"] * 3})
    ground = [no_wind.compute(_values(no_wind, [f.v_ned[k], f.euler[k]])) for k in range(len(f))]
    assert np.max(np.abs(np.array(ground) - f.alpha)) > 1.0  # the wind term matters: without it, off by degrees


def test_derived_signals_through_the_live_pipeline_from_a_tlog(windy, tmp_path: Path) -> None:
    """The tlog is read by ``analyse_log``: the frame parser, the vehicle table and the assembler of
    ``run --observe``, with the map's derived α (Euler angles, NED velocity and wind) and elevator (a normalised
    control through its throws)."""
    from monitor.service.alarm import AlarmConfig
    from monitor.service.fleet_file import Fleet, load_model
    from monitor.service.offline import analyse_log
    from tests.gains_files import hand_made_gains_file, paper_plant_sampled_at

    f = windy
    write_mavlink_tlog(tmp_path / "flight.tlog", f)
    (tmp_path / "map.toml").write_text(MAVLINK_MAP)
    plant = paper_plant_sampled_at(tmp_path / "plant.toml", H)  # the paper's plant at the log's 50 Hz
    gains = hand_made_gains_file(tmp_path / "gains.toml", str(plant))
    fleet = Fleet(load_model(str(plant), gains, signals_file=tmp_path / "map.toml"))
    records = analyse_log(tmp_path / "flight.tlog", fleet, AlarmConfig()).records
    assert len(records) >= len(f) - 1
    ks = [round((r.t * 1e6 - T0_US) / (H * 1e6)) for r in records]
    alpha = np.array([r.alpha for r in records])
    assert np.max(np.abs(alpha - f.alpha[ks])) < 2e-4  # float32 on the wire
    elevator = np.array([r.elevator for r in records])
    assert np.max(np.abs(elevator - f.elevator[ks])) < 0.01
    assert [r.y[0] for r in records] == pytest.approx(list(alpha))


def test_derived_signals_from_a_px4_ulog(steady, tmp_path: Path) -> None:
    """PX4's topics (quaternion, NED velocity, the 1 Hz horizontal wind held, the servo's normalised control, its
    PWM at 10 Hz held) through read_flight, each topic stamped 0.15-1.9 ms after the instant."""
    from monitor.link.flight_log import read_flight
    from monitor.link.onboard_log import open_onboard_log

    f = steady
    path = tmp_path / "windy.ulg"
    write_px4_ulog(path, f)
    log = open_onboard_log(path)
    smap = parse_signals(tomllib.loads(PX4_MAP)["signals"], "px4 map", 1, 1, log.layouts)
    rows = read_flight(str(path), smap, H, dataflash=log).samples[1]
    assert len(rows) >= len(f) - 2
    t0 = rows[0][0]
    by_k = {k - t0: v for k, v in rows}
    ks = sorted(by_k)
    alpha = np.array([by_k[k]["alpha"] for k in ks])
    assert np.max(np.abs(alpha - f.alpha[ks])) < 2e-4  # float32 in the log
    assert np.ptp(f.alpha[ks]) > 1.0
    assert np.max(np.abs([by_k[k]["elevator"] for k in ks] - f.elevator[ks])) < 0.01
    assert np.max(np.abs([by_k[k]["q"] for k in ks] - np.degrees(f.rates[ks, 1]))) < 1e-4
    assert all("alpha.velocity_ned[0]" not in v for v in by_k.values())  # the inputs are not signals of the sample
    # 10 Hz, held 0.2 s: from the first record on (after the first sample's), the control of its own instant
    pwm = np.array([by_k[k].get("elevator_pwm", np.nan) for k in ks])
    assert np.isnan(pwm[0]) and not np.isnan(pwm[1:]).any()
    own = [i for i in range(1, len(ks)) if ks[i] % 5 == 4]  # the sample just before the next PWM record
    assert len(own) > 30 and np.max(np.abs(pwm[own] - f.elevator[[ks[i] - 4 for i in own]])) < 0.01


@pytest.mark.parametrize(
    "edit, message",
    [
        ({"derive": "angle_of_atack"}, "unknown derivation 'angle_of_atack' (known: angle_of_attack, sideslip"),
        ({"field": "ATTITUDE.roll"}, "'angle_of_attack' takes no key 'field' (its keys: derive, unit, range"),
        ({"velocity_ned": ["LOCAL_POSITION_NED.vx"]}, "'velocity_ned' needs 3 fields (north, east, down)"),
        ({"attitude_euler": None}, "velocity_ned needs attitude_quaternion or attitude_euler to reach body axes"),
        ({"attitude_quaternion": ["ATTITUDE.roll"] * 4}, "give one of attitude_quaternion, attitude_euler, not"),
        ({"unit": "grad"}, "an angle's 'unit' is deg or rad, got 'grad'"),
        ({"wind_ned": ["WIND_COV.wind_x", "WIND_COV.wind_y", "WIND_COV.wind_q"]}, "WIND_COV has no field 'wind_q'"),
        ({"wind_ned": ["WIND_COV.wind_x", "WIND_COV.wind_y", {"field": "WIND_COV.wind_z", "unit": "m/s"}]}, "an input"),
        ({"velocity_body": ["ATTITUDE.roll"] * 3}, "give one of velocity_ned, velocity_body, not"),
        ({"derive": "__import__('os').system('true')"}, "unknown derivation"),
    ],
)
def test_a_bad_derivation_is_a_one_line_error(edit: dict, message: str) -> None:
    raw = tomllib.loads(MAVLINK_MAP)["signals"]
    spec = raw["measured"]["alpha"]
    for key, value in edit.items():
        if value is None:
            spec.pop(key)
        else:
            spec[key] = value
    with pytest.raises(UserError) as err:
        parse_signals(raw, "map", 1, 1)
    assert message in str(err.value) and "\n" not in str(err.value), str(err.value)


@pytest.mark.parametrize(
    "spec, message",
    [
        (
            {"derive": "pwm", "input": "SERVO_OUTPUT_RAW.servo2_raw", "pwm": [1500, 1000, 2000], "throw": 25},
            "min < trim",
        ),
        ({"derive": "pwm", "input": "SERVO_OUTPUT_RAW.servo2_raw", "throw": 25}, "'pwm' must be 3 finite number(s)"),
        ({"derive": "control", "input": "SERVO_OUTPUT_RAW.servo2_raw"}, "needs 'throw'"),
        ({"derive": "control", "input": "SERVO_OUTPUT_RAW.servo2_raw", "throw": [1, 2, 3]}, "'throw' must be 2"),
        ({"derive": "degrees"}, "needs input"),
    ],
)
def test_bad_scalar_derivations_are_one_line_errors(spec: dict, message: str) -> None:
    raw = tomllib.loads(MAVLINK_MAP)["signals"]
    raw["measured"]["elevator"] = spec
    with pytest.raises(UserError) as err:
        parse_signals(raw, "map", 1, 1)
    assert message in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_pwm_and_control_follow_their_stated_throws() -> None:
    pwm = _derivation({"derive": "pwm", "input": "x", "pwm": [1100, 1520, 1900], "throw": [-28.0, 23.0]})
    control = _derivation({"derive": "control", "input": "x", "throw": 25.0})
    at = {1100: -28.0, 1520: 0.0, 1900: 23.0, 1310: -14.0, 1710: 11.5}
    assert [pwm.compute({pwm.inputs[0]: x}) for x in at] == pytest.approx(list(at.values()))
    assert [control.compute({control.inputs[0]: x}) for x in (-1.0, 0.5)] == pytest.approx([-25.0, 12.5])


def test_a_derived_pwm_reads_a_dataflash_log_as_scale_and_offset_do(tmp_path: Path) -> None:
    """ArduPlane's RCOU.C2 (servo PWM) through ``pwm`` with symmetric throws is the map's scale and offset; q
    through ``radians`` and back through ``degrees`` is q: derived signals read DataFlash logs as any other."""
    from monitor.link.dataflash import open_dataflash
    from monitor.link.flight_log import read_flight
    from tests.dataflash_formats import ARDUPLANE_MAP, short_period_flight, write_dataflash

    _A, _B, samples = short_period_flight(seconds=5.0)
    path = tmp_path / "00000001.BIN"
    write_dataflash(path, samples, 0.02)
    derived = ARDUPLANE_MAP.replace(
        'elevator = { field = "RCOU.C2", scale = 0.06, offset = -90.0, unit = "deg" }',
        'elevator = { derive = "pwm", input = "RCOU.C2", pwm = [1000, 1500, 2000], throw = 30.0 }\n'
        'q_rad = { derive = "radians", input = "RATE.P" }',
    )
    assert derived != ARDUPLANE_MAP
    rows = {}
    for name, text in (("plain", ARDUPLANE_MAP), ("derived", derived)):
        dlog = open_dataflash(path)
        table = tomllib.loads(text)["signals"]
        smap = parse_signals({**table, "outputs": ["alpha", "q"]}, name, 2, 1, dlog.layouts)
        rows[name] = read_flight(str(path), smap, 0.02, dataflash=dlog).samples[1]
        dlog.close()
    assert len(rows["plain"]) == len(samples) == len(rows["derived"])
    for (k1, plain), (k2, mine) in zip(rows["plain"], rows["derived"], strict=True):
        assert k1 == k2 and mine["elevator"] == pytest.approx(plain["elevator"], abs=1e-9)
        assert math.degrees(mine["q_rad"]) == pytest.approx(plain["q"], rel=1e-12)
