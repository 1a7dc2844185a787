"""The flight condition of a point (``[signals] condition``), the bank's load factor as a schedule variable, and
the trims interpolated between an envelope's points (``monitor.model.scheduling.trim_weights``)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.link.signals import parse_signals
from monitor.model.envelope import assemble_envelope, parse_envelope
from monitor.model.flight_condition import needed_signals, schedule_value
from monitor.model.plant import parse_plant
from monitor.model.scheduling import make_schedule, outside_variables, trim_weights, values_in_order
from tests.envelope_files import short_period


def test_the_bank_load_factor_is_one_over_cos_bank_the_same_both_ways_and_needs_the_roll() -> None:
    for bank in (0.0, 30.0, 45.0, 60.0):
        n = 1.0 / math.cos(math.radians(bank))
        assert schedule_value("bank_load_factor", {"roll": bank}) == pytest.approx(n, rel=1e-12)
        assert schedule_value("bank_load_factor", {"roll": -bank}) == pytest.approx(n, rel=1e-12)
    assert schedule_value("bank_load_factor", {"roll": 90.0}) == pytest.approx(1 / math.cos(math.radians(85)))
    assert math.isnan(schedule_value("bank_load_factor", {"airspeed": 50.0}))
    assert math.isnan(schedule_value("bank_load_factor", {"roll": math.nan}))
    assert schedule_value("airspeed", {"airspeed": 50.0}) == 50.0
    assert needed_signals(["airspeed", "bank_load_factor", "roll"]) == ("airspeed", "roll")


def test_the_signed_bank_load_factor_is_the_extra_load_with_the_bank_s_sign() -> None:
    """``bank_load_factor_signed``: ``sign(roll) (1/cos(roll) - 1)``: zero wings level, opposite in a left and a
    right turn of one bank, so turn legs flown both ways are two places of the schedule."""
    for bank in (15.0, 45.0, 60.0):
        extra = 1.0 / math.cos(math.radians(bank)) - 1.0
        assert schedule_value("bank_load_factor_signed", {"roll": bank}) == pytest.approx(extra, rel=1e-12)
        assert schedule_value("bank_load_factor_signed", {"roll": -bank}) == pytest.approx(-extra, rel=1e-12)
    assert schedule_value("bank_load_factor_signed", {"roll": 0.0}) == 0.0
    assert needed_signals(["airspeed", "bank_load_factor_signed"]) == ("airspeed", "roll")
    assert math.isnan(schedule_value("bank_load_factor_signed", {"airspeed": 50.0}))


def test_trims_interpolate_linearly_on_one_variable_and_take_the_end_point_beyond() -> None:
    s = make_schedule(["airspeed"], ["a", "b", "c"], np.array([[30.0], [40.0], [60.0]]))
    for x, want in ((20, [1, 0, 0]), (30, [1, 0, 0]), (32.5, [0.75, 0.25, 0]), (45, [0, 0.75, 0.25]), (70, [0, 0, 1])):
        assert trim_weights(s, [x]) == pytest.approx(want, abs=1e-12), x
    # points that lie on one line in two variables: along that line, as on one variable
    line = make_schedule(["v", "n"], ["a", "b"], np.array([[30.0, 1.0], [40.0, 2.0]]))
    assert trim_weights(line, [35.0, 1.5]) == pytest.approx([0.5, 0.5])


def test_trims_interpolate_barycentrically_in_two_variables_exactly_for_a_linear_trim() -> None:
    at = np.array([[33.6, 1.0], [41.1, 1.0], [51.5, 1.0], [51.2, 1.414], [50.1, 2.0]])
    s = make_schedule(["airspeed", "bank_load_factor"], list("abcde"), at)
    trim = at @ np.array([0.3, -2.0]) + 1.0  # a trim linear in the schedule: interpolation must be exact inside
    rng = np.random.default_rng(0)
    inside = 0
    for x in rng.uniform([33.0, 1.0], [52.0, 2.0], size=(200, 2)):
        w = trim_weights(s, x)
        assert w.min() >= 0 and w.sum() == pytest.approx(1.0)
        if s.triangulation.find_simplex(x / s.scale) >= 0:
            inside += 1
            assert w @ trim == pytest.approx(float(x @ np.array([0.3, -2.0]) + 1.0), abs=1e-9)
        else:  # beyond the points' hull: between two of its corners (the hull's closest point), no extrapolation
            edge = sorted(np.flatnonzero(w > 1e-12).tolist())
            assert len(edge) == 1 or edge in [sorted(e) for e in hull_edges(s)]
    assert inside > 50
    # continuous across the hull: a walk from inside to outside moves the interpolated trim by small steps only
    walk = np.column_stack([np.full(400, 51.5), np.linspace(1.0, 2.0, 400)])
    trims = [trim_weights(s, x) @ trim for x in walk]
    assert max(abs(np.diff(trims))) < 5 * abs(trims[-1] - trims[0]) / 400
    for i, point in enumerate(at):  # a point's own place: that point alone
        assert trim_weights(s, point)[i] == pytest.approx(1.0)


def hull_edges(schedule) -> list[list[int]]:
    return [[int(a), int(b)] for a, b in schedule.triangulation.convex_hull]


def test_points_a_few_tenths_apart_are_one_level_of_the_identified_range() -> None:
    """Turn legs flown at cruise speed identify a few tenths of a m/s apart: the range above cruise is half the
    spacing to the next speed down, not half of those tenths."""
    at = np.array([[33.6, 1.0], [41.1, 1.0], [51.5, 1.0], [51.2, 1.414], [50.1, 2.0]])
    s = make_schedule(["airspeed", "bank_load_factor"], list("abcde"), at)
    assert outside_variables(s, [51.5 + 4.0, 1.0]) == []
    assert outside_variables(s, [51.5 + 5.5, 1.0]) == [0]  # past half of 51.5 - 41.1
    assert outside_variables(s, [50.1, 2.0 + 0.25]) == []  # half the spacing 1.414 -> 2.0 is 0.29
    assert outside_variables(s, [50.1, 2.0 + 0.35]) == [1]
    # a 60 deg turn at 45 m/s: each value in range, the combination beyond the hull (turns identified at cruise)
    assert outside_variables(s, [45.0, 2.0]) == [0, 1]


def test_the_condition_table_is_checked_and_places_a_point_by_the_bank(tmp_path: Path) -> None:
    measured = tomllib.loads(short_period(3.8, 0.0, -7.1))["signals"]
    measured["measured"]["roll"] = {"field": "ATTITUDE.roll", "scale": 57.29577951308232, "unit": "deg"}
    ok = dict(measured, condition={"roll": 45.0, "airspeed": 51.0})
    assert parse_signals(ok, "p.toml", 2, 1).condition == {"roll": 45.0, "airspeed": 51.0}
    for condition, message in (
        ({"bank": 45.0}, "names 'bank', which is not in [signals.measured]"),
        ({"alpha": 1.0}, "names 'alpha', an output or actuator signal"),
        ({"roll": "steep"}, "'roll' must be a finite number"),
        ({"roll": math.inf}, "'roll' must be a finite number"),
    ):
        with pytest.raises(UserError) as err:
            parse_signals(dict(measured, condition=condition), "p.toml", 2, 1)
        assert message in str(err.value) and "\n" not in str(err.value)
    # two legs at cruise, one level and one in a 60 deg turn: assembled by the bank's load factor (2 at 60 deg)
    plants = []
    for name, bank, trim in (("level", 0.2, (3.8, 0.0, -7.1)), ("turn60", -59.8, (7.5, 15.0, -13.0))):
        text = short_period(*trim).replace(
            'airspeed = { field = "VFR_HUD.airspeed", unit = "m/s" }',
            'airspeed = { field = "VFR_HUD.airspeed", unit = "m/s" }\n'
            'roll = { field = "ATTITUDE.roll", scale = 57.29577951308232, unit = "deg" }',
        )
        text = text.replace(
            "[signals.measured]", f"condition = {{ roll = {bank}, airspeed = 51.4 }}\n[signals.measured]"
        )
        plants.append((name, parse_plant(text, f"{name}.toml")))
    env = parse_envelope(assemble_envelope(plants, ["bank_load_factor"], "turns"), "turns.toml")
    assert env.names == ("level", "turn60")
    assert env.point("turn60").at["bank_load_factor"] == pytest.approx(1 / math.cos(math.radians(59.8)))
    schedule = make_schedule(env.schedule, env.names, env.at_matrix)
    assert values_in_order(schedule, {"roll": -45.0}) == [pytest.approx(math.sqrt(2))]
    assert values_in_order(schedule, {"airspeed": 50.0}) is None  # no roll in the sample
    # a point whose map does not measure the roll cannot be scheduled on its load factor: one line
    with pytest.raises(UserError) as err:
        assemble_envelope([("a", parse_plant(short_period(3.8, 0, -7.1), "a.toml"))] * 2, ["bank_load_factor"], "bad")
    assert "\n" not in str(err.value)
