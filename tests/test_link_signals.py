"""The signal map: the default is the contract's mapping; anything unknown is one line naming it."""

from __future__ import annotations

import tomllib

import pytest

from monitor.errors import UserError
from monitor.link.signals import DEFAULT_SIGNALS_TOML, default_signal_map, parse_signals, signals_for_plant
from monitor.model.plant import load_plant, parse_plant


def _raw() -> dict:
    return tomllib.loads(DEFAULT_SIGNALS_TOML)["signals"]


def test_default_map_is_the_contract() -> None:
    sig = default_signal_map()
    assert sig.instant == "AOA_SSA"
    assert [(sig.measured[s].message, sig.measured[s].field) for s in sig.outputs] == [("AOA_SSA", "AOA")]
    assert sig.measured["q"].scale == pytest.approx(57.29577951308232)
    assert sig.measured["elevator"].index == 0 and sig.command.channels == (1,) and sig.command.full_scale == (30.0,)
    assert sig.messages(observe=False) == ("AOA_SSA",)
    assert sig.messages(observe=True) == ("AOA_SSA", "ACTUATOR_OUTPUT_STATUS")
    assert signals_for_plant(load_plant("paper-continuous")) == sig


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda r: r["measured"].update(alpha={"field": "AOA_SSB.AOA"}), "unknown MAVLink message 'AOA_SSB'"),
        (lambda r: r["measured"].update(alpha={"field": "AOA_SSA.AOB"}), "AOA_SSA has no field 'AOB'"),
        (lambda r: r["measured"].update(elevator={"field": "ACTUATOR_OUTPUT_STATUS.actuator[32]"}), "out of range"),
        (lambda r: r["measured"].update(alpha={"field": "AOA_SSA.AOA", "scal": 2}), "unknown key 'scal'"),
        (lambda r: r.update(output=["alpha"]), "unknown key 'output'"),
        (lambda r: r.update(outputs=["alpha", "q"]), "plant has 1 output"),
        (lambda r: r.update(outputs=["beta"]), "'beta', which is not in [signals.measured]"),
        (
            lambda r: r["measured"].update(elevator={"field": "VFR_HUD.throttle"}),
            "VFR_HUD has no time_usec or time_boot_ms",
        ),
        (lambda r: r.update(instant="ATTITUDE"), "needs a time_usec field"),
        (lambda r: r["command"].update(channels=[9]), "channels must be in 0..7"),
    ],
)
def test_bad_maps_are_one_line_errors_naming_the_problem(edit, message: str) -> None:
    raw = _raw()
    edit(raw)
    with pytest.raises(UserError) as err:
        parse_signals(raw, "x.toml", 1, 1)
    assert message in str(err.value) and "\n" not in str(err.value)


SECOND_AIRFRAME = """
form = "continuous"
name = "alpha-q-airframe"
h = 0.02
tau_min = 0.0
tau_max = 0.008
A_c = [[-2.97, 3.95], [2.96, -6.92]]
B_c = [[-2.75], [6.71]]
D_cf = [[-0.069], [0.95]]
D_cd = [[-0.79], [1.53]]
C = [[1.0, 0.0], [0.0, 1.0]]

[signals]
instant = "AOA_SSA"
outputs = ["alpha", "q"]
actuator = ["elevator"]
[signals.measured]
alpha = { field = "AOA_SSA.AOA", unit = "deg" }
q = { field = "ATTITUDE.pitchspeed", scale = 57.29577951308232, unit = "deg/s" }
elevator = { field = "SERVO_OUTPUT_RAW.servo2_raw", scale = 0.06, offset = -90.0, unit = "deg" }
[signals.command]
channels = [4]
full_scale = [25.0]
"""


def test_a_plant_file_carries_its_own_map_and_the_hash_ignores_it() -> None:
    plant = parse_plant(SECOND_AIRFRAME, "airframe.toml")
    sig = signals_for_plant(plant)
    assert sig.outputs == ("alpha", "q") and sig.messages(False) == ("AOA_SSA", "ATTITUDE")
    assert sig.measured["elevator"].message == "SERVO_OUTPUT_RAW" and sig.command.channels == (4,)
    assert sig.measured["elevator"].scale * 2000 + sig.measured["elevator"].offset == 30.0
    assert sig.time_fields["SERVO_OUTPUT_RAW"][1] == 1  # time_usec
    without = parse_plant(SECOND_AIRFRAME.split("[signals]")[0], "airframe.toml")
    assert without.digest == plant.digest
    with pytest.raises(UserError, match="default signal map is for 1 and 1"):
        signals_for_plant(without)
