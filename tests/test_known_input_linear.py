"""Measured inputs besides the elevator (the throttle): ``[known_inputs.linear]`` in a plant file, its column added
to the prediction about the trim in ``[signals] condition``, and ``identify --known-input`` identifying the column
with the elevator's and writing it there, not into the plant's ``B_c``."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from scipy.linalg import expm

from monitor.errors import UserError
from monitor.model.identification import FlightData, identify
from monitor.model.plant import parse_plant
from monitor.model.plant_toml import plant_toml
from monitor.wire.specs import Excitation
from tests.envelope_files import short_period

THROTTLE = 'throttle = { field = "VFR_HUD.throttle", unit = "%" }'
A_C = np.array([[-2.36, 0.956], [-20.5, -4.38]])
B_ELEVATOR = np.array([-0.155, -13.8])
B_THROTTLE = np.array([0.004, 0.35])  # per percent: a nose-up pitching moment with power


def with_linear(linear: str, condition: str = "{ throttle = 62.0 }") -> str:
    text = short_period(3.8, 0.0, -7.1).replace(
        'airspeed = { field = "VFR_HUD.airspeed", unit = "m/s" }',
        f'airspeed = {{ field = "VFR_HUD.airspeed", unit = "m/s" }}\n{THROTTLE}',
    )
    if condition:
        text = text.replace("[signals.measured]", f"condition = {condition}\n[signals.measured]")
    return text + f"\n[known_inputs.linear]\n{linear}\n"


def test_the_linear_column_acts_on_the_deviation_from_the_trim() -> None:
    plant = parse_plant(with_linear("throttle = [0.004, 0.35]"), "p.toml")
    known = plant.known_inputs
    assert known is not None and known.terms == () and known.signals == ("throttle",)
    values = {"alpha": 3.8, "q": 0.0, "throttle": 72.0}
    assert known.vector(values) == pytest.approx([0.04, 3.5])  # 10 % above its trim of 62
    assert known.vector(values, {"throttle": 72.0}) == pytest.approx([0.0, 0.0])  # an envelope's trim, given
    assert known.vector({"alpha": 3.8, "q": 0.0}) is None  # no throttle in the sample: predicted without
    # the digest is the dynamics': the same plant without the table designs the same gains
    assert plant.digest == parse_plant(with_linear("throttle = [1.0, 2.0]"), "p.toml").digest


@pytest.mark.parametrize(
    "linear, condition, message",
    [
        (
            "rpm = [0.0, 1.0]",
            "{ throttle = 62.0 }",
            "key 'known_inputs.linear.rpm': 'rpm' is not in [signals.measured]",
        ),
        ("alpha = [0.0, 1.0]", "{ throttle = 62.0 }", "'alpha' is an output"),
        ("throttle = [0.0]", "{ throttle = 62.0 }", "must be a list of 2 finite numbers"),
        ("throttle = [0.0, nan]", "{ throttle = 62.0 }", "must be a list of 2 finite numbers"),
        ("throttle = [0.0, 1.0]", "", "needs its trim, 'throttle' in [signals] condition"),
    ],
)
def test_a_wrong_linear_table_is_one_line_naming_the_key(linear: str, condition: str, message: str) -> None:
    with pytest.raises(UserError) as err:
        parse_plant(with_linear(linear, condition), "p.toml")
    assert message in str(err.value) and "\n" not in str(err.value)


def two_input_flight(seed: int = 3, lag_s: float = 0.0) -> tuple[FlightData, float]:
    """The short-period model driven by an elevator PRBS and a slow throttle PRBS (the mission's dwells), after a
    quiet lead-in, sampled at 20 Hz; alpha, q in deviations + their trim. ``lag_s``: the throttle acts through a
    first-order lag of that time constant (an engine), integrated exactly with the plant."""
    h, lead = 0.05, 60
    n = 1200
    elevator = np.r_[np.zeros(lead), [s * 1.0 for s in Excitation(1.0, 40.0).signs(h, seed)]][:n]
    throttle = np.r_[np.zeros(lead), [s * 8.0 for s in Excitation(8.0, 40.0).signs(h, seed + 1, (2.0, 6.0))]][:n]
    elevator = np.r_[elevator, np.zeros(n - len(elevator))]
    throttle = np.r_[throttle, np.zeros(n - len(throttle))]
    # the state (alpha, q, thrust), the thrust a lag of the lever (or the lever itself: a very fast lag)
    rate = 1.0 / lag_s if lag_s > 0 else 1e4
    A = np.zeros((3, 3))
    A[:2, :2], A[:2, 2], A[2, 2] = A_C, B_THROTTLE, -rate
    B = np.zeros((3, 2))
    B[:2, 0], B[2, 1] = B_ELEVATOR, rate
    M = expm(np.block([[A, B], [np.zeros((2, 5))]]) * h)
    Ad, Bd = M[:3, :3], M[:3, 3:]
    z = np.zeros((n, 3))
    for k in range(n - 1):
        z[k + 1] = Ad @ z[k] + Bd @ np.array([elevator[k], throttle[k]])
    x = z[:, :2]
    trim = np.array([3.8, 0.0])
    data = FlightData(
        h=h,
        k=np.arange(n),
        states=x + trim,
        inputs=np.column_stack([elevator - 7.1, throttle + 62.0]),
        state_names=("alpha", "q"),
        input_names=("elevator", "throttle"),
    )
    return data, 62.0


def test_identify_finds_the_throttle_s_column_and_the_plant_file_keeps_it_apart_from_b_c() -> None:
    data, trim = two_input_flight()
    result = identify(data)
    assert result.B_c[:, 0] == pytest.approx(B_ELEVATOR, rel=0.02, abs=0.01)
    assert result.B_c[:, 1] == pytest.approx(B_THROTTLE, rel=0.05, abs=0.002)
    assert result.operating_point["throttle"] == pytest.approx(trim)
    signals = tomllib.loads(with_linear("throttle = [0.0, 0.0]"))["signals"]
    text = plant_toml(
        result,
        name="two-inputs",
        description="",
        tau_max=0.023,
        actuator_limit=25.0,
        actuator_limit_source="test",
        signals={k: v for k, v in signals.items() if k not in ("operating_point", "condition")},
        source_log="synthetic",
        model="short-period",
        condition={"airspeed": 51.4},
    )
    plant = parse_plant(text, "two-inputs.toml")
    raw = tomllib.loads(text)
    assert np.array(raw["B_c"]).shape == (2, 1) and np.array(raw["D_cf"]).shape == (2, 1)
    assert set(raw["signals"]["operating_point"]) == {"alpha", "q", "elevator"}  # the throttle's trim is not there
    assert raw["signals"]["condition"] == {"airspeed": 51.4, "throttle": pytest.approx(trim)}
    assert plant.known_inputs is not None
    assert plant.known_inputs.linear["throttle"] == pytest.approx(result.B_c[:, 1], rel=1e-5)


def test_lag_factor_and_lagged_are_the_exact_first_order_step() -> None:
    """A step through ``lagged`` is ``1 - exp(-t / T)`` at every sample, across a gap too; no lag is the input."""
    from monitor.model.known_inputs import lag_factor, lagged

    k = np.array([0, 1, 2, 3, 7, 8])
    out = lagged(np.array([0.0, 1.0, 1.0, 1.0, 1.0, 1.0]), k, 0.5, 0.1)
    t = k * 0.1  # the value read at a sample is taken as held over the interval that ends there
    assert out[1:] == pytest.approx(1.0 - np.exp(-t[1:] / 0.5), rel=1e-12)
    assert lagged(np.array([0.0, 1.0]), np.array([0, 1]), 0.0, 0.1).tolist() == [0.0, 1.0]
    assert lag_factor(0.0, 0.05) == 1.0 and lag_factor(2.0, 0.0) == 0.0


@pytest.mark.parametrize(
    "lag, message",
    [("throttle = -1.0", "must be a number of seconds >= 0"), ("rpm = 1.0", "'rpm' has no column")],
)
def test_a_wrong_lag_table_is_one_line_naming_the_key(lag: str, message: str) -> None:
    text = with_linear("throttle = [0.004, 0.35]") + f"\n[known_inputs.lag]\n{lag}\n"
    with pytest.raises(UserError) as err:
        parse_plant(text, "p.toml")
    assert message in str(err.value) and "known_inputs.lag" in str(err.value) and "\n" not in str(err.value)
    plant = parse_plant(with_linear("throttle = [0.004, 0.35]") + "\n[known_inputs.lag]\nthrottle = 1.5\n", "p")
    assert plant.known_inputs is not None and plant.known_inputs.lag == {"throttle": 1.5}


def test_identify_picks_the_engine_s_lag_and_then_finds_the_whole_column() -> None:
    """The throttle acting through a 1-s lag: the instant fit underrates its column; the lag picked from the grid
    by the held-out fit is the one flown, and the column with it is the true one."""
    from monitor.pipelines.identify_log import _identify_with_lags

    data, _trim = two_input_flight(lag_s=1.0)
    instant = identify(data)
    said: list[str] = []
    result, lags = _identify_with_lags(data, said.append)
    assert lags == {"throttle": 1.0} and "known input lag 1 s kept" in said[0]
    assert result.B_c[:, 1] == pytest.approx(B_THROTTLE, rel=0.05, abs=0.002)
    assert abs(instant.B_c[1, 1] - B_THROTTLE[1]) > 0.1 * B_THROTTLE[1]  # without the lag: off by a tenth or more
    data0, _ = two_input_flight()
    assert _identify_with_lags(data0, said.append)[1] == {"throttle": 0.0}  # no lag flown, none picked


def test_the_estimator_lags_the_signal_as_identify_did_and_restarts_with_the_vehicle() -> None:
    """``vehicles._lagged_inputs``: sample by sample (a lost sample one longer step) it gives what ``lagged`` gives
    over the same samples; a sample number going back (the vehicle restarted) starts the lag again; a missing
    value leaves the others lagged and is not invented."""
    from types import SimpleNamespace

    from monitor.model.known_inputs import lagged
    from monitor.service.vehicles import _lagged_inputs

    vehicle = SimpleNamespace(input_lagged=None)
    k = np.array([10, 11, 12, 15, 16])
    throttle = np.array([60.0, 70.0, 70.0, 55.0, 55.0])
    seen = [
        _lagged_inputs(vehicle, {"throttle": 1.0}, {"throttle": v, "alpha": 3.0}, int(i), 0.05)
        for i, v in zip(k, throttle, strict=True)
    ]
    assert [s["throttle"] for s in seen] == pytest.approx(lagged(throttle, k, 1.0, 0.05).tolist(), rel=1e-12)
    assert all(s["alpha"] == 3.0 for s in seen)
    assert _lagged_inputs(vehicle, {"throttle": 1.0}, {"throttle": 80.0}, 3, 0.05)["throttle"] == 80.0  # restarted
    assert "throttle" not in _lagged_inputs(vehicle, {"throttle": 1.0}, {"alpha": 1.0}, 4, 0.05)


@pytest.mark.parametrize("value, expected", [("auto", None), ("0", 0.0), ("2.5", 2.5)])
def test_the_lag_option_takes_seconds_or_auto(value: str, expected: float | None) -> None:
    from monitor.commands.identify import _lag

    assert _lag(value) == expected


@pytest.mark.parametrize("value", ["-1", "nan", "soon"])
def test_a_wrong_lag_option_is_refused(value: str) -> None:
    import argparse

    from monitor.commands.identify import _lag

    with pytest.raises(argparse.ArgumentTypeError, match="seconds >= 0 or 'auto'"):
        _lag(value)
