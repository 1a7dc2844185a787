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


def two_input_flight(seed: int = 3) -> tuple[FlightData, float]:
    """The short-period model driven by an elevator PRBS and a slow throttle PRBS (the mission's dwells), after a
    quiet lead-in, sampled at 20 Hz; alpha, q in deviations + their trim."""
    h, lead = 0.05, 60
    n = 1200
    elevator = np.r_[np.zeros(lead), [s * 1.0 for s in Excitation(1.0, 40.0).signs(h, seed)]][:n]
    throttle = np.r_[np.zeros(lead), [s * 8.0 for s in Excitation(8.0, 40.0).signs(h, seed + 1, (2.0, 6.0))]][:n]
    elevator = np.r_[elevator, np.zeros(n - len(elevator))]
    throttle = np.r_[throttle, np.zeros(n - len(throttle))]
    M = expm(np.block([[A_C, np.column_stack([B_ELEVATOR, B_THROTTLE])], [np.zeros((2, 4))]]) * h)
    Ad, Bd = M[:2, :2], M[:2, 2:]
    x = np.zeros((n, 2))
    for k in range(n - 1):
        x[k + 1] = Ad @ x[k] + Bd @ np.array([elevator[k], throttle[k]])
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
