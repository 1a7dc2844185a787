"""Missions (``sim-vehicle run --aircraft NAME --mission FILE``): the file's strict reader, and the on-board autopilot
flying real JSBSim aircraft in process (``sim_vehicle/autopilot.py`` inside ``JSBSimFlightModel.fly``, driven by
``Simulation`` without sockets). No mocks.

What is held, in calm air: c172p banks to 45 and 60 deg within 3 deg and holds altitude within 100 ft (measured:
10 ft at 60 deg), reaches the end of a slow-down within 3 kt (measured: 0.1 kt) and a heading within 3 deg; the
737, a second and very different aircraft (an airliner at 250 kt, elevator and engines of its own), flies a turn
with the same gains; a segment an aircraft cannot fly is one line naming it; with ``compensation`` a command from
outside is added to the autopilot's elevator after its delay, and the sample reports all three. Each flight is at
most ~150 simulated seconds (under a second of CPU).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.wire.mavlink import new_codec
from monitor.wire.specs import parse_delay_spec, parse_fault_spec
from monitor.wire.telemetry import AircraftSample, encode_sample, quantities
from sim_vehicle.autopilot import AIRSPEED_RATE_KT_S, ALTITUDE_RATE_FPM, BANK_RATE_DEG_S, HEADING_BANK_LIMIT_DEG
from sim_vehicle.flight_model import FlightModelError
from sim_vehicle.jsbsim_model import AircraftSpec, JSBSimFlightModel, stall_alpha
from sim_vehicle.mission import Mission, load_mission, parse_mission
from sim_vehicle.simulation import Simulation
from tests.sim_recorder import Recorder

REPO = Path(__file__).resolve().parent.parent
EXAMPLE = REPO / "docs" / "examples" / "mission-manoeuvres.toml"


def segment(name: str, duration: float, airspeed: float, **kw: object) -> dict:
    """One [[segment]] table (level at 3000 ft, wings level, unless ``kw`` says otherwise)."""
    table: dict = {"name": name, "duration": duration, "airspeed": airspeed}
    if "climb" not in kw:
        table["altitude"] = 3000
    if "heading" not in kw:
        table["bank"] = 0
    table.update(kw)
    return table


def mission(*segments: dict) -> Mission:
    return parse_mission({"segment": list(segments)}, "test.toml")


def fly(
    name: str,
    plan: Mission,
    compensation: bool = False,
    fault: str | None = None,
    delay: str = "const:0.02",
    answer=None,
) -> tuple[Simulation, Recorder, FlightModelError | None]:
    """Fly ``plan`` to its end (or until the aircraft cannot go on); ``answer(sim, sample)`` may send commands."""
    first = plan.segments[0]
    model = JSBSimFlightModel(
        AircraftSpec(name, airspeed_kt=first.airspeed_kt, altitude_ft=first.altitude_ft or 3000.0, mission=plan)
    )
    rec = Recorder()
    sim = Simulation(
        None,
        rec,
        steps=plan.steps(model.h),
        model=model,
        fault=parse_fault_spec(fault),
        delay=parse_delay_spec(delay),
        compensation=compensation,
    )
    stopped = None
    answered = -1
    try:
        while not sim.done:
            sim.run_until(sim.next_time())
            if answer is not None and rec.samples and rec.samples[-1].k > answered:  # each sample once, when sent
                answered = rec.samples[-1].k
                answer(sim, rec.samples[-1])
    except FlightModelError as exc:
        stopped = exc
    model.close()
    return sim, rec, stopped


def column(truth: list[dict], key: str, segment_name: str, after: float = 0.0) -> np.ndarray:
    """``key`` over the samples of one segment, from ``after`` seconds into it."""
    rows = [t for t in truth if t["segment"] == segment_name]
    start = rows[0]["t"]
    return np.array([t[key] for t in rows if t["t"] >= start + after - 1e-9])


# -- the file ---------------------------------------------------------------------------------------------------------


def test_the_example_mission_parses_into_its_segments_back_to_back() -> None:
    m = load_mission(EXAMPLE)
    names = [s.name for s in m.segments]
    assert names[0] == "level" and "turn-60" in names and "slow-down" in names and names[-1] == "identification"
    assert [s.start for s in m.segments[1:]] == pytest.approx(np.cumsum([s.duration for s in m.segments[:-1]]))
    assert m.duration == 560 and m.steps(0.05) == 11200
    banks = {s.bank_deg for s in m.segments if s.bank_deg is not None}
    assert {30.0, -45.0, 60.0} <= banks and {s.climb_fpm for s in m.segments} >= {500.0, -500.0}
    assert str(m.segments[-1].excite) == "prbs:1:30" and m.segments[0].airspeed_kt == 100


def test_the_rate_limits_are_the_ones_the_documentation_states() -> None:
    text = (REPO / "docs" / "missions.md").read_text()
    assert (AIRSPEED_RATE_KT_S, ALTITUDE_RATE_FPM, BANK_RATE_DEG_S, HEADING_BANK_LIMIT_DEG) == (1, 500, 10, 30)
    for stated in ("1 kt/s", "500 ft/min", "10 deg/s", "30 deg"):
        assert stated in text, stated


GOOD = {"name": "a", "duration": 10, "airspeed": 90, "altitude": 3000, "bank": 0}


@pytest.mark.parametrize(
    "raw, message",
    [
        ({"segment": [{**GOOD, "bnak": 3}]}, "segment 1 ('a'): unknown key 'bnak' (known: name, duration"),
        ({"segment": [{**GOOD, "bank": "30"}]}, "segment 1 ('a'): key 'bank': expected a number, got '30'"),
        ({"segment": [{**GOOD, "duration": True}]}, "segment 1 ('a'): key 'duration': expected a number, got True"),
        ({"segment": [{k: v for k, v in GOOD.items() if k != "airspeed"}]}, "segment 1 ('a'): key 'airspeed': missing"),
        ({"segment": [{k: v for k, v in GOOD.items() if k != "name"}]}, "segment 1: key 'name': missing"),
        ({"segment": [{**GOOD, "duration": 0}]}, "segment 1 ('a'): key 'duration': must be positive (seconds), got 0"),
        ({"segment": [{**GOOD, "airspeed": -5}]}, "key 'airspeed': must be positive (knots, calibrated), got -5"),
        ({"segment": [{**GOOD, "bank": 80}]}, "segment 1 ('a'): key 'bank': must be within +-75 deg, got 80"),
        ({"segment": [{**GOOD, "altitude": -20}]}, "key 'altitude': must be above the ground"),
        (
            {"segment": [GOOD, {**GOOD, "name": "b", "heading": 400, "bank": None}]},
            "key 'heading': must be in [0, 360]",
        ),
        ({"segment": [{**GOOD, "climb": 500}]}, "segment 1 ('a'): needs exactly one of 'altitude' (ft) and 'climb'"),
        ({"segment": [{**GOOD, "heading": 90}]}, "segment 1 ('a'): needs exactly one of 'bank' and 'heading'"),
        (
            {"segment": [{**{k: v for k, v in GOOD.items() if k != "altitude"}, "climb": 500}]},
            "segment 1 ('a'): key 'altitude': missing (the aircraft is trimmed at the first segment's altitude)",
        ),
        ({"segment": [GOOD, GOOD]}, "segment 2 ('a'): key 'name': another segment has this name"),
        ({"segment": [{**GOOD, "excite": "prbs:1"}]}, "segment 1 ('a'): key 'excite': bad --excite SPEC 'prbs:1'"),
        ({"segment": [{**GOOD, "excite": 1}]}, "segment 1 ('a'): key 'excite': expected a string"),
        ({"segment": [{**GOOD, "excite": "prbs:1:30"}]}, "the PRBS lasts 30 s, longer than the segment (10 s)"),
        ({"segment": [{**GOOD, "excite_throttle": "prbs:5:5"}]}, "key 'excite_throttle' needs 'excite'"),
        (
            {"segment": [{**GOOD, "excite": "prbs:1:5", "excite_throttle": "prbs:60:5"}]},
            "key 'excite_throttle': the amplitude is in percent of throttle, at most 50",
        ),
        (
            {"segment": [{**GOOD, "excite": "prbs:1:5", "excite_throttle": "prbs:5:20"}]},
            "key 'excite_throttle': the PRBS lasts 20 s, longer than the segment (10 s)",
        ),
        ({"segment": [{**GOOD, "excite": "prbs:1:5", "excite_throttle": 5}]}, "key 'excite_throttle': expected a"),
        ({"segment": [GOOD], "speed": 3}, "unknown key 'speed' (a mission file holds [[segment]] tables only)"),
        ({}, "expected one or more [[segment]] tables"),
    ],
)
def test_a_mistake_in_a_mission_is_one_line_naming_the_file_the_segment_and_the_key(raw: dict, message: str) -> None:
    raw = {**raw, "segment": [{k: v for k, v in s.items() if v is not None} for s in raw.get("segment", [])]}
    if not raw["segment"]:
        del raw["segment"]
    with pytest.raises(UserError) as caught:
        parse_mission(raw, "m.toml")
    text = str(caught.value)
    assert text.startswith("--mission m.toml: ") and message in text and "\n" not in text, text


def test_a_file_that_is_not_toml_or_not_there_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[[segment]]\nname = \n")
    with pytest.raises(UserError, match=r"^--mission .*bad.toml: not valid TOML: "):
        load_mission(bad)
    with pytest.raises(UserError, match=r"^--mission .*none.toml: cannot read: "):
        load_mission(tmp_path / "none.toml")


def test_the_throttle_prbs_is_slow_and_independent_of_the_elevator_s() -> None:
    m = mission(segment("a", 1, 90), segment("b", 60, 90, excite="prbs:1:50", excite_throttle="prbs:8:50"))
    timeline = m.timeline(0.05, seed=4)
    times = [1.0 + 0.05 * i + 0.01 for i in range(1000)]
    elevator = np.array([timeline.at(t)[1] for t in times])
    throttle = np.array([timeline.throttle_at(t) for t in times])
    assert set(throttle) == {-8.0, 8.0} and set(elevator) == {-1.0, 1.0}
    switches = np.flatnonzero(np.diff(throttle))
    assert len(switches) >= 5 and np.diff(switches).min() >= 2.0 / 0.05 - 1  # dwells of 2 s and more
    assert abs(np.corrcoef(elevator, throttle)[0, 1]) < 0.2  # two inputs, not one
    assert timeline.throttle_at(0.5) == 0.0 and timeline.throttle_at(55.0) == 0.0  # outside the PRBS: none


def test_the_timeline_names_the_segment_flown_and_its_prbs_level() -> None:
    m = mission(segment("a", 2, 90), segment("b", 3, 90, excite="prbs:2:1"))
    timeline = m.timeline(0.05, seed=4)
    assert timeline.at(0.0)[0].name == "a" and timeline.at(1.99)[0].name == "a"
    levels = [timeline.at(2.0 + 0.05 * i + 0.01) for i in range(30)]
    assert all(s.name == "b" for s, _ in levels)
    assert {v for _, v in levels[:20]} == {-2.0, 2.0} and {v for _, v in levels[20:]} == {0.0}  # 1 s of PRBS, then 0
    assert timeline.at(99.0)[0].name == "b"  # after the end: the last segment


# -- the autopilot, flying ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def c172p_manoeuvres() -> tuple[Simulation, Recorder, FlightModelError | None]:
    """c172p: a 45 deg and a 60 deg turn holding altitude, a slow-down to 65 kt, a heading of 90 deg (165 s)."""
    plan = mission(
        segment("level", 5, 100),
        segment("turn-45", 25, 100, bank=45),
        segment("turn-60", 25, 100, bank=60),
        segment("wings-level", 10, 100),
        segment("slow-down", 60, 65),
        segment("east", 40, 65, heading=90),
    )
    return fly("c172p", plan)


def test_c172p_banks_as_commanded_and_holds_its_altitude_in_45_and_60_degree_turns(c172p_manoeuvres) -> None:
    sim, rec, stopped = c172p_manoeuvres
    assert stopped is None and len(rec.truth) == 3300
    for name, bank in (("turn-45", 45.0), ("turn-60", 60.0)):
        rolled_in = column(rec.truth, "bank_deg", name, after=bank / BANK_RATE_DEG_S + 3.0)  # roll-in: 10 deg/s
        assert np.abs(rolled_in - bank).max() < 3.0, (name, rolled_in.min(), rolled_in.max())
        altitude = column(rec.truth, "altitude_ft", name)
        assert np.abs(altitude - 3000.0).max() < 100.0, (name, altitude.min(), altitude.max())  # measured: 10 ft
        load = column(rec.truth, "load_factor", name, after=10.0)  # JSBSim's Nz: 1/cos(bank) in a level turn
        assert load.mean() == pytest.approx(1.0 / math.cos(math.radians(bank)), rel=0.05)
    assert column(rec.truth, "airspeed_kt", "turn-60", after=10.0).min() > 95.0  # throttle up: airspeed kept too


def test_c172p_reaches_the_slow_down_s_airspeed_and_a_heading_without_oscillating(c172p_manoeuvres) -> None:
    sim, rec, stopped = c172p_manoeuvres
    slow = column(rec.truth, "airspeed_kt", "slow-down")
    assert abs(slow[-1] - 65.0) < 3.0 and slow.min() > 62.0  # reached, no undershoot past 3 kt
    late = column(rec.truth, "airspeed_kt", "east")
    assert np.abs(late - 65.0).max() < 3.0  # and held through the turn to the east
    assert np.abs(column(rec.truth, "altitude_ft", "slow-down") - 3000.0).max() < 100.0
    heading = column(rec.truth, "heading_deg", "east", after=30.0)
    assert np.abs(heading - 90.0).max() < 3.0
    bank = column(rec.truth, "bank_deg", "east")
    assert np.abs(bank).max() <= HEADING_BANK_LIMIT_DEG + 3.0  # heading hold banks at most 30 deg
    # no oscillation: over the slow-down's last 20 s the airspeed and the altitude have settled
    assert np.abs(column(rec.truth, "airspeed_kt", "slow-down", after=40.0) - 65.0).max() < 1.0
    assert np.ptp(column(rec.truth, "altitude_ft", "slow-down", after=40.0)) < 20.0


def test_the_737_a_second_very_different_aircraft_flies_a_turn_with_the_same_autopilot() -> None:
    plan = mission(segment("level", 5, 250), segment("turn-45", 30, 250, bank=-45), segment("out", 10, 250))
    sim, rec, stopped = fly("737", plan)
    assert stopped is None
    bank = column(rec.truth, "bank_deg", "turn-45", after=45 / BANK_RATE_DEG_S + 3.0)
    assert np.abs(bank + 45.0).max() < 3.0
    assert np.abs(np.array([t["altitude_ft"] for t in rec.truth]) - 3000.0).max() < 100.0  # measured: 15 ft
    assert np.abs(np.array([t["airspeed_kt"] for t in rec.truth]) - 250.0).max() < 3.0
    assert np.abs(column(rec.truth, "bank_deg", "out", after=8.0)).max() < 3.0  # rolled out


@pytest.mark.parametrize(
    "target, message",
    [
        (
            140,
            r"c172p: cannot hold 140 kt in segment 'fast' at t = \d+\.\d s: throttle at full for 5 s, airspeed 1\d\d",
        ),
        (40, r"c172p: stalls in segment 'fast' at t = \d+\.\d s: alpha 1\d\.\d deg, above its stall alpha 16\.0 deg"),
    ],
)
def test_a_segment_the_aircraft_cannot_fly_stops_it_with_one_line(target: float, message: str) -> None:
    sim, rec, stopped = fly("c172p", mission(segment("level", 2, 100), segment("fast", 120, target)))
    assert stopped is not None
    text = str(stopped)
    assert re.match(message, text) and "\n" not in text, text
    assert len(rec.truth) < 1200  # stopped on the way, not at the end


def test_the_stall_alpha_comes_from_the_aircraft_s_own_files() -> None:
    import jsbsim

    root = Path(jsbsim.get_default_root_dir()) / "aircraft"
    c172p = JSBSimFlightModel(AircraftSpec("c172p"))
    cub = JSBSimFlightModel(AircraftSpec("J3Cub", airspeed_kt=60))
    # c172p defines <alphalimits> (aero/alpha-max-rad = 0.28); J3Cub's lift table peaks at 0.2182 rad
    assert stall_alpha(c172p.fdm, root / "c172p" / "c172p.xml") == (
        pytest.approx(16.04, abs=0.01),
        "aero/alpha-max-rad",
    )
    assert stall_alpha(cub.fdm, root / "J3Cub" / "J3Cub.xml") == (
        pytest.approx(12.50, abs=0.01),
        "the peak of its lift table",
    )
    assert stall_alpha(cub.fdm, None) == (15.0, "the default")


# -- who moves the elevator -------------------------------------------------------------------------------------------


def test_with_compensation_a_command_received_is_added_to_the_autopilot_s_elevator_after_its_delay() -> None:
    def answer(sim: Simulation, sample: AircraftSample) -> None:
        if sample.k == 40:  # +1.5 deg answering sample 40, arriving at once; the drawn delay is 0.02 s
            assert sim.receive_command(40, 1.5, sim.airframe.t) == "scheduled"

    sim, rec, stopped = fly("c172p", mission(segment("level", 4, 100)), compensation=True, answer=answer)
    assert stopped is None and sim.stats.commands["applied"] == 1
    before, after = rec.samples[:41], rec.samples[41:]
    assert all(s.compensation == 0.0 and s.elevator_deg == pytest.approx(s.autopilot_elevator) for s in before)
    assert all(s.compensation == 1.5 for s in after)
    assert all(s.elevator_deg == pytest.approx(s.autopilot_elevator + 1.5) for s in after)  # actuator[0] = the sum
    assert rec.truth[40]["tau"] == pytest.approx(0.02)  # acted after its delay, not at once
    assert rec.truth[40]["status"] == "applied" and rec.truth[40]["compensation"] == 0.0
    assert rec.truth[41]["compensation"] == 1.5
    assert rec.truth[41]["surface"] == pytest.approx(rec.samples[41].elevator_deg)  # no fault: the surface is the sum
    # the autopilot answers the disturbance: its own part moves down by about the compensation (theta held)
    assert rec.samples[-1].autopilot_elevator == pytest.approx(rec.samples[40].autopilot_elevator - 1.5, abs=0.3)
    # the wire: ACTUATOR_OUTPUT_STATUS.actuator[0..2] = applied, autopilot's, compensation
    last = rec.samples[-1]
    msgs = {m.get_type(): m for m in new_codec(255, 190).parse_buffer(encode_sample(new_codec(1, 1), last, 0.05))}
    actuator = msgs["ACTUATOR_OUTPUT_STATUS"].actuator
    assert actuator[:3] == pytest.approx([last.elevator_deg, last.autopilot_elevator, 1.5], abs=1e-5)


def test_without_compensation_commands_from_outside_are_counted_and_ignored() -> None:
    def answer(sim: Simulation, sample: AircraftSample) -> None:
        assert sim.receive_command(sample.k, 5.0, sim.airframe.t) == "ignored_autopilot"

    sim, rec, stopped = fly("c172p", mission(segment("level", 1, 100)), answer=answer)
    assert sim.stats.commands["ignored_autopilot"] == 20 and sim.stats.commands["applied"] == 0
    assert all(s.compensation == 0.0 and s.elevator_deg == s.autopilot_elevator for s in rec.samples)
    assert sim.stats.samples["onboard"] == 20 and {t["status"] for t in rec.truth} == {"onboard"}


def test_faults_act_at_the_surface_after_the_autopilot_s_servo() -> None:
    plan = mission(segment("level", 3, 100))
    sim, rec, _ = fly("c172p", plan, fault="bias:2@20")
    servo = np.array([t["elevator"] for t in rec.truth])
    surface = np.array([t["surface"] for t in rec.truth])
    assert np.allclose(surface[:21], servo[:21], atol=1e-9) and np.allclose(surface[21:], servo[21:] + 2.0, atol=1e-9)
    # the autopilot fights the bias it cannot see: its elevator moves about 2 deg the other way
    assert rec.samples[-1].autopilot_elevator == pytest.approx(rec.samples[20].autopilot_elevator - 2.0, abs=0.4)
    sim, rec, _ = fly("c172p", plan, fault="stuck@30")
    held = [t["elevator"] for t in rec.truth[31:]]
    assert max(held) == min(held) == pytest.approx(rec.truth[30]["elevator"], abs=0.2)  # frozen where it was


def test_a_mission_sample_carries_the_attitude_rates_throttle_altitude_and_climb_the_truth_reports() -> None:
    sim, rec, _ = fly("c172p", mission(segment("level", 1, 100), segment("turn", 4, 100, bank=30, altitude=3100)))
    truth, sample = rec.truth[-1], rec.samples[-1]
    have = quantities(sample)
    assert {"roll", "yaw", "p", "r", "throttle", "altitude", "climb", "autopilot_elevator", "compensation"} <= set(have)
    assert have["roll"] == pytest.approx(truth["bank_deg"], abs=1e-6) and have["roll"] > 20.0
    assert have["altitude"] == pytest.approx(truth["altitude_ft"] * 0.3048, abs=1e-3)
    assert have["climb"] * 60 / 0.3048 == pytest.approx(truth["climb_fpm"], rel=1e-6) and have["climb"] > 0.5
    assert abs(have["throttle"] - 100 * truth["throttle"]) <= 1.0  # VFR_HUD carries whole percent
    assert truth["segment"] == "turn" and truth["reference"]["bank_deg"] == pytest.approx(30.0)
    assert {"airspeed_kt", "load_factor", "bank_deg", "altitude_ft", "autopilot_elevator", "compensation"} <= set(truth)


def test_an_identification_leg_holds_stick_and_throttle_and_reports_each_prbs_switch_at_its_instant() -> None:
    """The sample at k reports the deflection applied from k h: the held elevator plus the PRBS level of k (a report
    one step late carried each switch to the monitor a sample late, which read it as a fault of the switch's size)."""
    plan = mission(segment("level", 2, 100), segment("prbs", 6, 100, excite="prbs:1:5"))
    sim, rec, stopped = fly("c172p", plan)
    assert stopped is None
    leg = [(s, t) for s, t in zip(rec.samples, rec.truth, strict=True) if t["segment"] == "prbs"]
    first_sample, first_truth = leg[0]
    held = first_sample.autopilot_elevator - first_truth["excitation"]
    levels = {t["excitation"] for _s, t in leg}
    assert levels >= {1.0, -1.0}  # the PRBS switched within the leg
    for s, t in leg:
        assert s.autopilot_elevator == pytest.approx(held + t["excitation"], abs=1e-9), s.k
        assert s.elevator_deg == pytest.approx(s.autopilot_elevator, abs=1e-9)  # no compensation: the report is it
        assert t["throttle"] == pytest.approx(first_truth["throttle"], abs=1e-12)  # the throttle held
    # with excite_throttle, the held throttle plus its PRBS (in fractions of full throttle)
    plan = mission(segment("level", 2, 100), segment("prbs", 6, 100, excite="prbs:1:5", excite_throttle="prbs:5:5"))
    sim, rec, stopped = fly("c172p", plan)
    assert stopped is None
    leg = [t for t in rec.truth if t["segment"] == "prbs"]
    timeline = plan.timeline(sim.h, seed=0)
    held = leg[0]["throttle"] - timeline.throttle_at(2.0) / 100.0
    assert {round(t["throttle"] - held, 9) for t in leg[:-20]} <= {0.05, -0.05}
    assert len({t["throttle"] for t in leg}) >= 2


def test_a_throttle_at_full_while_the_airspeed_still_climbs_back_is_no_failure_and_a_stuck_one_is() -> None:
    """The watch, fed directly: 25 kt below the reference at full throttle, regaining 0.5 kt/s (a pa28 after a
    60-deg turn) for 30 s is no trouble; the same error with the airspeed stuck is, after the 5-s stop."""
    from sim_vehicle.autopilot import Autopilot, Targets, Trim

    trim = Trim(0.0, 0.0, 0.0, 1.0, 0.0, 90.0, 3000.0, 20.0)
    dt = 1.0 / 120.0
    targets = Targets(airspeed_kt=90.0, altitude_ft=3000.0, bank_deg=0.0)
    for rate, troubled in ((0.5, False), (0.0, True)):
        pilot = Autopilot(trim, (-20.0, 20.0), dt, 15.0)
        pilot.throttle = 1.0
        airspeed = 65.0
        for _ in range(int(30.0 / dt)):
            pilot._watch(2.0, airspeed, targets, ramping=False)
            airspeed += rate * dt
        assert (pilot.trouble is not None) == troubled, pilot.trouble
        if troubled:
            assert pilot.trouble is not None and pilot.trouble[0] == "cannot hold 90 kt"
