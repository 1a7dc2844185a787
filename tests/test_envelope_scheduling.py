"""Scheduling an envelope in ``run`` and ``analyse``: the pure parts (the point with hysteresis, the identified range,
re-basing the state), the vehicle table on synthetic samples (switching, outside, the alarm paused, the payload),
``analyse`` of a telemetry log (per-point counts, the recording) and single-point models unchanged."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.gains import write_gains
from monitor.link.dialect import layout_by_name
from monitor.link.tlog import TlogWriter
from monitor.model.closed_loop import Gains
from monitor.model.envelope import load_envelope
from monitor.model.plant import parse_plant
from monitor.model.scheduling import (
    HYSTERESIS,
    choose_point,
    make_schedule,
    outside_variables,
    rebase,
    state_offset,
)
from monitor.service.alarm import DEFAULT_ALARM, AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.pipeline import Pipeline
from monitor.service.publisher import estimate_payload
from monitor.service.vehicles import VehicleTable
from monitor.wire.mavlink import mavlink, new_codec
from tests.aircraft_files import AIRCRAFT_PLANT, GAINS
from tests.envelope_files import A_C, B_C, SP_GAINS, plant_text, short_period, trim_at

DEG = 57.29577951308232
H_US = 50_000
ATT, AOA, ACT, HUD = (layout_by_name(n) for n in ("ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS", "VFR_HUD"))


# --- files ---------------------------------------------------------------------------------------------------------


def _indent(text: str) -> str:
    """A single-point plant file as an envelope's ``[point.plant]`` (its tables moved under it)."""
    return re.sub(r"^\[(\[?)", r"[\1point.plant.", text, flags=re.M)


def envelope_files(
    directory: Path, points: list[tuple[str, float, str]], gains: dict[str, Gains], name: str = "test"
) -> tuple[Path, Path]:
    """An envelope plant file of ``(name, airspeed, single-point plant text)`` points scheduled by airspeed, and its
    gains file with the gains given per point (a common certificate claimed by hand: nothing here verifies it)."""
    from monitor.design.envelope import CommonCertificate, EnvelopeDesign
    from monitor.design.solve import Solved
    from monitor.gains import write_envelope_gains

    text = f'form = "envelope"\nname = "{name}"\nschedule = ["airspeed"]\n'
    for point, V, plant in points:
        text += f'\n[[point]]\nname = "{point}"\nat = {{ airspeed = {V} }}\n[point.plant]\n{_indent(plant)}'
    env_path, gains_path = directory / f"{name}.toml", directory / f"{name}-gains.toml"
    env_path.write_text(text)
    env = load_envelope(env_path)
    results = {
        p: DesignResult(
            "certified", gains[p], gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0
        )
        for p, _V, _t in points
    }
    common = CommonCertificate(
        P=np.eye(1),
        gamma=1.0,
        solved=Solved("by hand", "claimed", 0.0),
        vertices={p: np.zeros((1, 1)) for p in results},
    )
    write_envelope_gains(gains_path, EnvelopeDesign(envelope=env, method="certified", results=results, common=common))
    return env_path, gains_path


def single_files(directory: Path, text: str, gains: Gains, name: str = "single") -> tuple[Path, Path]:
    plant_path, gains_path = directory / f"{name}.toml", directory / f"{name}-gains.toml"
    plant_path.write_text(text)
    result = DesignResult(
        "certified", gains, gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0
    )
    write_gains(gains_path, result, parse_plant(text, str(plant_path)))
    return plant_path, gains_path


AIRSPEEDS = (40.0, 51.4, 62.0)


def c172p_envelope(directory: Path) -> tuple[Path, Path]:
    """The c172p of ``tests/envelope_files.py`` at 40, 51.4 and 62 m/s (airspeed is one of its outputs)."""
    points = [(f"v{V:g}".replace(".", "_"), V, plant_text(V)) for V in AIRSPEEDS]
    return envelope_files(directory, points, {p: GAINS for p, _V, _t in points}, name="c172p-env")


# --- messages ------------------------------------------------------------------------------------------------------


def messages(k: int, alpha: float, q: float, theta: float, elevator: float, airspeed: float) -> list[tuple[str, tuple]]:
    """One sample's messages, VFR_HUD first (a latest value: it serves the sample whose parts follow it)."""
    t = k * H_US
    return [
        ("VFR_HUD", HUD.decode(HUD.unpacker.pack(airspeed, airspeed, 100.0, 0.0, 90, 60))),
        ("ATTITUDE", ATT.decode(ATT.unpacker.pack(t // 1000, 0.0, theta / DEG, 0.0, 0.0, q / DEG, 0.0))),
        ("AOA_SSA", AOA.decode(AOA.unpacker.pack(t, alpha, 0.0))),
        ("ACTUATOR_OUTPUT_STATUS", ACT.decode(ACT.unpacker.pack(t, 1, elevator, *[0.0] * 31))),
    ]


class Publisher:
    """The publisher interface, keeping what the loop hands over."""

    def __init__(self) -> None:
        self.items: list[tuple] = []
        self.alarms: list[tuple] = []
        self.published = self.dropped = 0

    def estimate(self, item: tuple) -> None:
        self.items.append(item)

    def alarm(self, *args) -> None:
        self.alarms.append(args)


class Records:
    def __init__(self) -> None:
        self.records: list = []

    def submit(self, record) -> None:
        self.records.append(record)


def pipeline_for(model, alarm: AlarmConfig = DEFAULT_ALARM) -> tuple[Pipeline, Publisher, Records]:
    table = VehicleTable(Fleet(model), alarm, timeout=float("inf"), observe=True)
    publisher, records = Publisher(), Records()
    return (
        Pipeline(table, send_commands=False, gcs_feedback=False, publisher=publisher, recorder=records),
        publisher,
        records,
    )


def fly(pipeline: Pipeline, rows: list[tuple[float, float, float, float, float]], sysid: int = 1) -> None:
    """``rows``: (alpha, q, theta, elevator, airspeed) per sample, k = 0, 1, ..."""
    for k, row in enumerate(rows):
        now = k * H_US * 1e-6
        for name, values in messages(k, *row):
            pipeline.on_message(sysid, name, values, now, now)


def c172p_row(V: float) -> tuple[float, float, float, float, float]:
    """What the aircraft would show flying level at V (the trim the c172p envelope's points are scaled with)."""
    trim = trim_at(V)
    return (trim["alpha"], 0.0, trim["theta"], trim["elevator"], V)


# --- the pure parts ------------------------------------------------------------------------------------------------


def _line(*at: float):
    return make_schedule(["airspeed"], [f"p{i}" for i in range(len(at))], np.array(at).reshape(-1, 1))


def test_the_point_switches_past_a_dead_band_about_the_midpoint_and_never_chatters() -> None:
    sched = _line(40.0, 50.0, 60.0)
    # 10 % of the spacing of 10: from p0 to p1 beyond 45.5, back below 44.5
    assert choose_point(sched, [45.4], 0) == 0 and choose_point(sched, [45.6], 0) == 1
    assert choose_point(sched, [44.6], 1) == 1 and choose_point(sched, [44.4], 1) == 0
    assert choose_point(sched, [45.4], None) == 1  # the first sample: the nearest
    assert choose_point(sched, [58.0], 0) == 2  # a jump over a point: to the nearest
    rng = np.random.default_rng(0)
    wander = 45.0 + 0.49 * np.sin(np.arange(500) * 0.7) + rng.uniform(-0.005, 0.005, 500)  # about the midpoint
    for start in (0, 1):
        point = start
        for x in wander:
            point = choose_point(sched, [x], point)
            assert point == start
    # without the band, the same wander chatters: the hysteresis is what stops it
    point, switches = 0, 0
    for x in wander:
        new = choose_point(sched, [x], point, margin=0.0)
        switches += new != point
        point = new
    assert switches > 100
    # a sweep up and back down switches once each way, at the band's edges
    sweep = np.concatenate([np.arange(40.05, 47.0, 0.1), np.arange(46.95, 40.0, -0.1)])
    point, used = 0, []
    for x in sweep:
        point = choose_point(sched, [x], point)
        used.append(point)
    turn = int(np.argmax(np.diff(sweep) < 0)) + 1
    assert used == [int(x > 45.5) for x in sweep[:turn]] + [int(x > 44.5) for x in sweep[turn:]]
    assert HYSTERESIS == 0.1


def test_two_variables_weigh_alike_and_keep_the_band() -> None:
    sched = make_schedule(["airspeed", "bank"], ["a", "b", "c"], np.array([[40.0, 0.0], [60.0, 0.0], [40.0, 60.0]]))
    assert choose_point(sched, [41.0, 5.0], None) == 0
    assert choose_point(sched, [40.0, 31.0], 0) == 0  # 31 of 60: past the midpoint, inside the band (33)
    assert choose_point(sched, [40.0, 33.1], 0) == 2


def test_outside_the_identified_range_is_half_a_spacing_beyond_the_outermost_points() -> None:
    sched = _line(36.0, 42.0, 48.0, 55.0, 62.0)
    assert outside_variables(sched, [33.0]) == [] and outside_variables(sched, [32.9]) == [0]  # 36 - 6/2
    assert outside_variables(sched, [65.5]) == [] and outside_variables(sched, [65.6]) == [0]  # 62 + 7/2
    assert outside_variables(sched, [50.0]) == [] and outside_variables(sched, [float("nan")]) == [0]
    two = make_schedule(["airspeed", "bank"], ["a", "b"], np.array([[40.0, 0.0], [60.0, 0.0]]))
    assert outside_variables(two, [50.0, 45.0]) == []  # every point at one bank: bank bounds nothing
    assert outside_variables(two, [29.0, 0.0]) == [0]


def test_a_combination_beyond_the_points_hull_is_outside_on_both_variables() -> None:
    """The turn legs flown at cruise only (c172p's identification flight): a 45 deg turn at approach speed is
    within each variable's range but a tenth of the spreads beyond the points' hull: outside, on both."""
    from monitor.model.scheduling import HULL_MARGIN, hull_gap

    at = np.array([[33.4, 1.0], [41.2, 1.0], [51.5, 1.0], [51.7, 1.414], [50.8, 2.0]])
    sched = make_schedule(["airspeed", "bank_load_factor"], ["65", "80", "100", "45", "60"], at)
    turn_at_approach = [33.4, 1.414]
    assert hull_gap(sched, turn_at_approach) > HULL_MARGIN
    assert outside_variables(sched, turn_at_approach) == [0, 1]
    assert hull_gap(sched, [45.0, 1.2]) == 0.0 and outside_variables(sched, [45.0, 1.2]) == []  # inside the hull
    # just beyond the cruise turns' edge (a knot fast between the 45 and 60 deg turns): within the margin, inside;
    # past the fastest point the per-variable margin rules (the value is clipped to the range before the hull)
    assert 0.0 < hull_gap(sched, [51.6, 1.7]) < HULL_MARGIN and outside_variables(sched, [51.6, 1.7]) == []
    assert hull_gap(sched, [54.0, 1.414]) == 0.0 and outside_variables(sched, [54.0, 1.414]) == []
    # the gap is the distance to the hull's closest point in the scaled variables (independent: the edge 65-60)
    scale = np.ptp(at, axis=0)
    a, b, p = at[0] / scale, at[4] / scale, np.array(turn_at_approach) / scale
    t = float(np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1))
    assert hull_gap(sched, turn_at_approach) == pytest.approx(float(np.linalg.norm(p - a - t * (b - a))), rel=1e-12)


def test_re_basing_to_another_point_and_back_is_the_identity() -> None:
    rng = np.random.default_rng(1)
    n, q, m, lags = 4, 1, 1, 2
    C = rng.normal(size=(3, 4))  # not square: the least-squares trim of the states
    a = state_offset(C, rng.normal(size=3), rng.normal(size=m), n + m * lags, q, lags)
    b = state_offset(C, rng.normal(size=3), rng.normal(size=m), n + m * lags, q, lags)
    z = rng.normal(size=n + m * lags + q + m)
    assert np.allclose(rebase(rebase(z, a, b), b, a), z, rtol=0, atol=1e-12)
    # C = I (identified models): the states move by exactly y0_i - y0_j, the commands by u0_i - u0_j, f_hat not
    y0_i, y0_j, u0_i, u0_j = [1.0, 2.0], [1.5, 1.0], [-7.1], [-4.3]
    wi = state_offset(np.eye(2), y0_i, u0_i, 2, 1)
    wj = state_offset(np.eye(2), y0_j, u0_j, 2, 1)
    z = np.array([0.1, 0.2, 0.7, 0.3])  # x_hat (2), f_hat, u(k-1)
    assert rebase(z, wi, wj) == pytest.approx([0.1 - 0.5, 0.2 + 1.0, 0.7, 0.3 - 2.8])
    # a lagged plant's commands in flight move with u(k-1)
    lagged = state_offset(np.eye(2), y0_i, u0_i, 2 + 2, 1, lag_slots=2)
    assert lagged.tolist() == [1.0, 2.0, -7.1, -7.1, 0.0, -7.1]


# --- the vehicle table ---------------------------------------------------------------------------------------------


def test_switching_between_two_trims_of_one_model_does_not_move_f_hat_at_all(tmp_path: Path) -> None:
    """Two points with the same matrices and operating points that are both equilibria of them (A_c dx + B_c du = 0):
    the envelope's f_hat is the single point's exactly, switching back and forth on a non-output airspeed and its
    trim interpolated between the two; the state is the single point's expressed about the interpolated trim."""
    du = 2.8
    dx = -np.linalg.solve(A_C, B_C[:, 0] * du)
    a, b = (3.8, 0.0, -7.1), (3.8 + dx[0], dx[1], -7.1 + du)
    env, env_gains = envelope_files(
        tmp_path,
        [("slow", 40.0, short_period(*a)), ("fast", 50.0, short_period(*b))],
        {"slow": SP_GAINS, "fast": SP_GAINS},
    )
    single, single_gains = single_files(tmp_path, short_period(*a), SP_GAINS)
    rng = np.random.default_rng(2)
    speeds = np.concatenate([np.linspace(38, 52, 60), np.linspace(52, 38, 60), 45.0 + 3.0 * np.sin(np.arange(80))])
    rows = [
        (3.8 + rng.normal(0, 1.0), rng.normal(0, 3.0), 0.0, -7.1 + rng.normal(0, 1.0) + (2.0 if k > 50 else 0), V)
        for k, V in enumerate(speeds)
    ]
    runs = []
    for plant, gains in ((env, env_gains), (single, single_gains)):
        pipeline, _pub, records = pipeline_for(load_model(plant, gains))
        fly(pipeline, rows)
        runs.append((pipeline, records.records))
    (pipeline, scheduled), (_p, reference) = runs
    assert [r.k for r in scheduled] == [r.k for r in reference] == list(range(len(rows)))
    vehicle = pipeline.table.vehicles[1]
    assert vehicle.switches >= 4 and {r.point for r in scheduled} == {0, 1}
    for s, r, V in zip(scheduled, reference, speeds, strict=True):
        assert s.f_hat == pytest.approx(r.f_hat, rel=1e-9, abs=1e-9), s.k
        # x_hat is about the trim interpolated at V (linear from 40 to 50 m/s, each end's beyond): the slow one's
        # moved by that share of dx; the trims are equilibria of the model, and so is every blend of them
        # (VFR_HUD.airspeed crosses the wire as a float32: the share is of the value received)
        share = min(max((float(np.float32(V)) - 40.0) / 10.0, 0.0), 1.0)
        assert np.allclose(s.x_hat, np.array(r.x_hat) - share * dx, rtol=0, atol=1e-9), s.k
        assert s.inside


def test_a_sweep_across_the_envelope_switches_points_flags_outside_and_pauses_the_alarm(tmp_path: Path, caplog) -> None:
    env, gains = c172p_envelope(tmp_path)
    model = load_model(env, gains)
    assert model.envelope is not None and model.name == "c172p-env"
    # the alarm raises on the first sample at or above a tiny threshold and never clears
    pipeline, publisher, records = pipeline_for(model, AlarmConfig(1e-6, 0.0, 1))
    speeds = np.arange(70.0, 29.9, -0.25)
    with caplog.at_level(logging.INFO, logger="monitor.service.vehicles"):
        fly(pipeline, [c172p_row(V) for V in speeds])
    recs = records.records
    assert len(recs) == len(speeds)
    names = model.envelope.names
    assert names == ("v40", "v51_4", "v62")
    used = [names[r.point] for r in recs]
    # from 62 to 51.4 below 56.7 - 0.53 (half the band of 10 % of the spacing 10.6), to 40 below 45.7 - 0.57
    assert used == ["v62" if V > 56.17 else "v51_4" if V > 45.13 else "v40" for V in speeds]
    outside = [not r.inside for r in recs]
    assert outside == [V > 62.0 + 5.3 or V < 40.0 - 5.7 for V in speeds]  # half the spacing beyond the ends
    assert pipeline.table.counters.outside_envelope == sum(outside) > 0
    # outside at the start, f_hat already above the threshold (70 m/s is far from any trim), yet no alarm
    first_inside = outside.index(False)
    assert max(max(abs(f) for f in r.f_hat) for r in recs[:first_inside]) > 1e-6
    assert not any(r.alarm for r in recs[:first_inside])
    assert recs[first_inside].alarm and len(publisher.alarms) == 1 and publisher.alarms[0][3] == "raised"
    # one WARNING per episode (two), an INFO when back inside
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [
        "vehicle 1: airspeed 70.0 m/s outside the identified envelope 40.0-62.0 m/s: fault alarms paused",
        "vehicle 1: airspeed 34.2 m/s outside the identified envelope 40.0-62.0 m/s: fault alarms paused",
    ]
    back = [r.getMessage() for r in caplog.records if "back inside" in r.getMessage()]
    assert back == [
        f"vehicle 1: airspeed 67.2 m/s back inside the identified envelope after {first_inside} sample(s) outside: "
        "fault alarms resume"
    ]
    switches = [r.getMessage() for r in caplog.records if "envelope point" in r.getMessage()]
    assert len(switches) == 2 and switches[0].startswith("vehicle 1: envelope point v62 -> v51_4 at k=")
    # the Zenoh estimate says which point and whether inside; the summary counts the samples outside
    payloads = [estimate_payload(item, "deg") for item in publisher.items]
    assert [p["point"] for p in payloads] == used and [p["in_envelope"] for p in payloads] == [not o for o in outside]
    assert f"outside envelope {sum(outside)}" in pipeline.summary()


def test_a_controlling_monitor_re_bases_its_last_command_so_a_switch_is_not_a_command_lost(tmp_path: Path) -> None:
    """Closed loop: the vehicle reports the command it was sent (absolute); the monitor judges it against its last
    command, a deviation, which a switch re-bases into the new point's trim (else every switch is 'not applied')."""
    env, gains = c172p_envelope(tmp_path)
    table = VehicleTable(Fleet(load_model(env, gains)), DEFAULT_ALARM)
    sent = None
    points = []
    for k, V in enumerate(np.linspace(60.0, 42.0, 80)):
        alpha, q, theta, elevator, _V = c172p_row(V)
        ready = []
        for name, values in messages(k, alpha, q, theta, elevator if sent is None else sent, V):
            ready += table.message(1, name, values, "r", k * 0.05)
        for vehicle, sample in ready:
            p = table.process(vehicle, sample, k * 0.05, k * 0.05)
            assert p is not None
            sent, _ = p.u_abs[0], points.append(p.point)
    assert points[0] == 2 and points[-1] == 0 and table.vehicles[1].switches == 2
    assert table.counters.not_applied == 0 and table.vehicles[1].commands_effective


def test_a_value_wandering_about_a_midpoint_keeps_its_point(tmp_path: Path) -> None:
    env, gains = c172p_envelope(tmp_path)
    pipeline, _pub, records = pipeline_for(load_model(env, gains))
    mid = 0.5 * (51.4 + 62.0)
    fly(pipeline, [c172p_row(mid + 0.5 * np.sin(0.9 * k)) for k in range(200)])  # within the band of +-0.53
    assert {r.point for r in records.records} == {1} or {r.point for r in records.records} == {2}
    assert pipeline.table.vehicles[1].switches == 0


def test_a_schedule_signal_that_is_not_an_output_is_needed_by_the_assembler(tmp_path: Path, caplog) -> None:
    """The short-period points' airspeed is measured, not an output: a sample waits for it as for an output, and a
    vehicle that never sends it is told so."""
    env, gains = envelope_files(
        tmp_path,
        [("a", 40.0, short_period(3.8, 0.0, -7.1)), ("b", 50.0, short_period(3.0, 0.0, -5.0))],
        {
            "a": SP_GAINS,
            "b": SP_GAINS,
        },
    )
    table = VehicleTable(Fleet(load_model(env, gains)), AlarmConfig(), observe=True)
    for k in range(3):
        for name, values in messages(k, 3.8, 0.0, 0.0, -7.1, 45.0)[1:]:  # no VFR_HUD
            assert table.message(1, name, values, "r", 0.0) == []
    with caplog.at_level(logging.WARNING, logger="monitor.service.vehicles"):
        assert table.warn_missing(10.0) == [1]
    assert "but never becomes a sample: missing VFR_HUD" in caplog.text
    ready = []
    for name, values in messages(3, 3.8, 0.0, 0.0, -7.1, 48.0):
        ready += table.message(1, name, values, "r", 10.0)
    # the first VFR_HUD releases the newest sample that only lacked it (k = 2; 0 and 1 dropped), then k = 3
    assert [s.k for _v, s in ready] == [2, 3] and all(s.values["airspeed"] == 48.0 for _v, s in ready)
    p = table.process(*ready[0], 10.0)
    assert p is not None and p.point == 1 and p.inside


def test_a_single_point_plant_is_unchanged(tmp_path: Path) -> None:
    plant, gains = single_files(tmp_path, AIRCRAFT_PLANT, GAINS)
    pipeline, publisher, records = pipeline_for(load_model(plant, gains))
    fly(pipeline, [c172p_row(51.4 + 0.1 * k) for k in range(20)])
    payload = estimate_payload(publisher.items[-1], "deg")
    assert list(payload) == [
        "sysid",
        "k",
        "t",
        "f_hat",
        "x_hat",
        "residual",
        "u",
        "tau",
        "alarm",
        "unit",
        "command_applied",
        "commands_effective",
    ]
    assert all(r.point is None and r.inside is None for r in records.records)
    assert "outside" not in pipeline.summary() and "outside_envelope" not in pipeline.counts()
    # an 11-element item (the contract's fields alone) still makes the same payload
    assert estimate_payload(publisher.items[-1][:11], "deg") == payload


def test_mismatched_plant_and_gains_are_one_line_errors(tmp_path: Path) -> None:
    env, env_gains = c172p_envelope(tmp_path)
    single, single_gains = single_files(tmp_path, AIRCRAFT_PLANT, GAINS)
    with pytest.raises(UserError, match="is a single-point gains file"):
        load_model(env, single_gains)
    with pytest.raises(UserError, match="is an envelope gains file .* not with"):
        load_model(single, env_gains)
    with pytest.raises(UserError, match="--signals does not apply to the envelope plant"):
        load_model(env, env_gains, signals_file=single)
    other, other_gains = envelope_files(
        tmp_path, [("a", 40.0, plant_text(40.0)), ("b", 62.0, plant_text(62.0))], {"a": GAINS, "b": GAINS}, "other"
    )
    with pytest.raises(UserError, match="has gains for points a, b; the envelope .* has points v40, v51_4, v62"):
        load_model(env, other_gains)


def test_the_ready_line_names_the_envelope_and_its_points(tmp_path: Path) -> None:
    from monitor.service.daemon import MonitorConfig, _operating_points

    env, gains = c172p_envelope(tmp_path)
    config = MonitorConfig(fleet=Fleet(load_model(env, gains)), connections=[])
    assert _operating_points(config) == (
        "; envelope c172p-env scheduled by airspeed: v40 (airspeed 40 m/s), v51_4 (airspeed 51.4 m/s), "
        "v62 (airspeed 62 m/s)"
    )


# --- analyse: a telemetry log --------------------------------------------------------------------------------------


def write_log(path: Path, rows: list[tuple[float, float, float, float, float]], sysid: int = 1) -> None:
    codec = new_codec(sysid, 1)
    with TlogWriter(path) as w:
        for k, (alpha, q, theta, elevator, V) in enumerate(rows):
            t_us = k * H_US
            for i, m in enumerate(
                (
                    mavlink.MAVLink_vfr_hud_message(V, V, 90, 60, 100.0, 0.0),
                    mavlink.MAVLink_attitude_message(t_us // 1000, 0, theta / DEG, 0, 0, q / DEG, 0),
                    mavlink.MAVLink_aoa_ssa_message(t_us, alpha, 0.0),
                    mavlink.MAVLink_actuator_output_status_message(t_us, 1, [elevator] + [0.0] * 31),
                )
            ):
                codec.send(m)
                w.write(1_700_000_000_000_000 + t_us + i * 1000, codec.file.take())


def test_analyse_reports_per_point_counts_and_records_the_point(tmp_path: Path, capsys) -> None:
    from monitor.service.recording_reader import load_recording

    env, gains = c172p_envelope(tmp_path)
    speeds = np.arange(70.0, 29.9, -0.25)
    log = tmp_path / "sweep.tlog"
    write_log(log, [c172p_row(V) for V in speeds])
    rrd = tmp_path / "sweep.rrd"
    assert main(["analyse", str(log), "--plant", str(env), "--gains", str(gains), "--json", "--rrd", str(rrd)]) == 0
    report = json.loads(capsys.readouterr().out)
    envelope = report["envelope"]
    counts = {p["name"]: (p["samples"], p["outside"]) for p in envelope["points"]}
    v62 = int(np.sum(speeds > 56.17))
    v40 = int(np.sum(speeds <= 45.13))
    assert counts == {
        "v62": (v62, int(np.sum(speeds > 67.3))),
        "v51_4": (len(speeds) - v62 - v40, 0),
        "v40": (v40, int(np.sum(speeds < 34.3))),
    }
    assert envelope["samples"] == len(speeds) and report["log"]["outside_envelope"] == envelope["outside"]
    # the recording: the point's index and inside per sample, the points' names in the properties
    recording = load_recording(rrd)
    assert recording.envelope_points == ["v40", "v51_4", "v62"]
    samples = recording.vehicles[1].samples
    assert [recording.envelope_points[s.point] for s in samples] == [
        "v62" if V > 56.17 else "v51_4" if V > 45.13 else "v40" for V in speeds
    ]
    assert [s.inside for s in samples] == [34.3 <= V <= 67.3 for V in speeds]
    assert json.loads(recording.properties["envelope_schedule"]) == ["airspeed"]
    # the text report lists the points
    assert main(["analyse", str(log), "--plant", str(env), "--gains", str(gains)]) == 0
    out = capsys.readouterr().out
    assert f"envelope c172p-env scheduled by airspeed: {len(speeds)} samples, {envelope['outside']} outside" in out
    assert re.search(rf"point v62 +\(airspeed 62 m/s\): {v62} samples, {counts['v62'][1]} outside", out)


def test_a_single_point_recording_reads_back_without_points(tmp_path: Path, capsys) -> None:
    from monitor.service.recording_reader import load_recording

    plant, gains = single_files(tmp_path, AIRCRAFT_PLANT, GAINS)
    log, rrd = tmp_path / "flight.tlog", tmp_path / "flight.rrd"
    write_log(log, [c172p_row(51.4) for _ in range(20)])
    assert main(["analyse", str(log), "--plant", str(plant), "--gains", str(gains), "--json", "--rrd", str(rrd)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert "envelope" not in report and "outside_envelope" not in report["log"]
    recording = load_recording(rrd)
    assert recording.envelope_points is None
    assert all(s.point is None and s.inside is None for s in recording.vehicles[1].samples)
