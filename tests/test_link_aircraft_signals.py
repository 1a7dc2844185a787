"""An aircraft's signal map: the operating point (deviations in, absolute deflections out) and VFR_HUD, a
message without a time field, read as a latest value (sample and hold). No sockets: the assembler, the
vehicle table and the offline path are driven with decoded messages and a telemetry log."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.link.assembly import SampleAssembler
from monitor.link.dialect import layout_by_name
from monitor.link.signals import parse_signals
from monitor.link.tlog import TlogWriter
from monitor.model.estimator import Estimator
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.offline import analyse_log
from monitor.service.vehicles import VehicleTable
from monitor.wire.mavlink import mavlink, new_codec
from tests.aircraft_files import AIRCRAFT_PLANT, GAINS, LIMIT, OP, SIGNALS, U0, Y0, aircraft_files

DEG = 57.29577951308232
H = 0.05
H_US = 50_000


def _raw() -> dict:
    return tomllib.loads(SIGNALS)["signals"]


def _map(raw: dict | None = None):
    return parse_signals(_raw() if raw is None else raw, "c172p.toml", 4, 1)


ATT, AOA, ACT, HUD = (layout_by_name(n) for n in ("ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS", "VFR_HUD"))


def att(k: int, q_deg_s: float = 0.0, theta: float = 2.31) -> tuple:
    return ATT.decode(
        ATT.unpacker.pack((k * H_US // 1000) & 0xFFFFFFFF, 0.0, theta / DEG, 0.0, 0.0, q_deg_s / DEG, 0.0)
    )


def aoa(k: int, alpha: float = 2.31) -> tuple:
    return AOA.decode(AOA.unpacker.pack(k * H_US, alpha, 0.0))


def act(k: int, elevator: float = -4.3) -> tuple:
    return ACT.decode(ACT.unpacker.pack(k * H_US, 1, elevator, *[0.0] * 31))


def hud(airspeed: float) -> tuple:
    return HUD.decode(HUD.unpacker.pack(airspeed, airspeed, 100.0, 0.0, 90, 60))


def speeds(samples) -> list[float]:
    return [round(s.values["airspeed"], 3) for s in samples]


# --- the signal map ---------------------------------------------------------------------------------


def test_the_contract_map_parses_with_its_operating_point_and_vfr_hud() -> None:
    sig = _map()
    assert sig.operating_point == OP
    assert sig.y0 == (2.31, 0.0, 2.31, 51.4) and sig.u0 == (-4.3,)
    assert sig.messages(observe=False) == ("AOA_SSA", "ATTITUDE", "VFR_HUD")
    assert sig.messages(observe=True) == ("AOA_SSA", "ATTITUDE", "VFR_HUD", "ACTUATOR_OUTPUT_STATUS")
    assert not sig.measured["airspeed"].timed and sig.measured["airspeed"].hold == 1.0
    assert sig.measured["alpha"].timed and "VFR_HUD" not in sig.time_fields
    assert sig.describe_operating_point() == (
        "operating point alpha 2.31 deg, q 0 deg/s, theta 2.31 deg, airspeed 51.4 m/s, elevator -4.3 deg"
    )
    assert "y3=VFR_HUD.airspeed (latest value)" in sig.describe()
    # deviation in: y - y0 and u - u0; absolute out: u0 + u
    y, u = sig.deviations({"alpha": 3.31, "q": -1.0, "theta": 2.0, "airspeed": 50.4, "elevator": -6.3})
    assert np.allclose(y, [1.0, -1.0, -0.31, -1.0]) and u == pytest.approx([-2.0])
    assert sig.deviations({"alpha": 3.31, "q": -1.0, "theta": 2.0, "airspeed": 50.4})[1] is None
    assert sig.absolute([1.5]) == pytest.approx([-2.8])


def test_without_an_operating_point_the_values_are_the_deviations() -> None:
    raw = _raw()
    del raw["operating_point"]
    sig = _map(raw)
    assert sig.operating_point is None and sig.describe_operating_point() is None
    assert sig.y0 == (0.0,) * 4 and sig.u0 == (0.0,)
    values = {"alpha": 3.31, "q": -1.0, "theta": 2.0, "airspeed": 50.4, "elevator": -6.3}
    assert sig.deviations(values) == ([3.31, -1.0, 2.0, 50.4], [-6.3])  # bit for bit: x - 0.0 is x
    assert sig.absolute([1.5]) == [1.5]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda r: r["operating_point"].pop("theta"), "operating_point: missing 'theta'"),
        (lambda r: [r["operating_point"].pop(n) for n in ("q", "elevator")], "missing 'q', 'elevator'"),
        (
            lambda r: r["operating_point"].update(beta=1.0),
            "operating_point: names 'beta', which is not in [signals.measured]",
        ),
        (
            lambda r: (
                r["measured"].update(rpm={"field": "VFR_HUD.throttle"}),
                r["operating_point"].update(rpm=2400.0),
            ),
            "names 'rpm', which is not an output or actuator signal",
        ),
        (lambda r: r["operating_point"].update(alpha="2.31"), "'alpha' must be a finite number"),
        (lambda r: r["operating_point"].update(alpha=math.nan), "'alpha' must be a finite number"),
        (lambda r: r["operating_point"].update(alpha=True), "'alpha' must be a finite number"),
        (lambda r: r.update(operating_point=[2.31, 0.0]), "operating_point: must be a table"),
        (
            lambda r: r["measured"]["alpha"].update(range=[-20.0, 20.0]) or r["operating_point"].update(alpha=25.0),
            "'alpha' = 25 is outside its range [-20, 20]",
        ),
        (
            lambda r: r["measured"].update(elevator={"field": "VFR_HUD.throttle"}),
            "actuator 'elevator': VFR_HUD has no time_usec or time_boot_ms",
        ),
        (
            lambda r: r["measured"]["elevator"].update(hold=0.5),
            "actuator 'elevator': 'hold' makes it a latest value, and the actuator report must be matched",
        ),
        (lambda r: r["measured"]["airspeed"].update(hold=0), "'hold' must be a positive number of seconds"),
        (lambda r: r.update(instant="VFR_HUD"), "needs a time_usec field"),
    ],
)
def test_bad_operating_points_and_timeless_uses_are_one_line_errors(edit, message: str) -> None:
    raw = _raw()
    edit(raw)
    with pytest.raises(UserError) as err:
        _map(raw)
    assert message in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_an_operating_deflection_beyond_the_actuator_limit_is_refused(tmp_path: Path) -> None:
    plant, gains = aircraft_files(tmp_path, AIRCRAFT_PLANT.replace("elevator = -4.3 }", "elevator = -30.0 }"))
    with pytest.raises(UserError, match=r"'elevator' = -30 is not inside the actuator limit \+-25"):
        load_model(plant, gains)


# --- assembly: VFR_HUD as a latest value --------------------------------------------------------------


def test_vfr_hud_in_the_sample_s_datagram_joins_its_sample_in_any_position() -> None:
    """sim-vehicle's order (ATTITUDE, AOA_SSA, VFR_HUD, ACTUATOR_OUTPUT_STATUS) and VFR_HUD first."""
    for order in (
        ["ATTITUDE", "AOA_SSA", "VFR_HUD", "ACTUATOR_OUTPUT_STATUS"],
        ["VFR_HUD", "AOA_SSA", "ATTITUDE", "ACTUATOR_OUTPUT_STATUS"],
        ["AOA_SSA", "VFR_HUD", "ACTUATOR_OUTPUT_STATUS", "ATTITUDE"],
    ):
        asm = SampleAssembler(_map(), H)
        got = []
        for k in range(5):
            msgs = {"ATTITUDE": att(k), "AOA_SSA": aoa(k), "VFR_HUD": hud(50.0 + k), "ACTUATOR_OUTPUT_STATUS": act(k)}
            for name in order:  # one message per datagram: each one filed on its own
                got += asm.add(name, msgs[name], "r", 0.001 * k)
        assert [s.k for s in got] == list(range(5)), order
        assert speeds(got) == [50.0, 51.0, 52.0, 53.0, 54.0], order
        c = asm.counters
        assert (c.incomplete, c.held_missing, c.waited_out) == (0, 0, 0)
        assert c.late_parts == (1 if order[-1] == "ACTUATOR_OUTPUT_STATUS" else 0)  # k = 0's report, before the
        # vehicle is known to send one, comes after the sample went: only a first ACTUATOR_OUTPUT_STATUS last


def test_vfr_hud_after_its_sample_was_processed_serves_the_next_one_and_the_first_sample_waits() -> None:
    """A vehicle that does not report its actuator: the sample goes when AOA_SSA and ATTITUDE are in."""
    asm = SampleAssembler(_map(), H)
    assert asm.add("AOA_SSA", aoa(0), "r", 0.0) == []
    assert asm.add("ATTITUDE", att(0), "r", 0.0) == []  # no airspeed heard yet: the first sample waits for one
    first = asm.add("VFR_HUD", hud(50.0), "r", 0.0)
    assert [s.k for s in first] == [0] and speeds(first) == [50.0]
    got = []
    for k in range(1, 4):
        got += asm.add("AOA_SSA", aoa(k), "r", 0.0)
        got += asm.add("ATTITUDE", att(k), "r", 0.0)  # processed here, with the value held from before
        assert asm.add("VFR_HUD", hud(50.0 + k), "r", 0.0) == []  # too late for k: held for k + 1
    assert [s.k for s in got] == [1, 2, 3] and speeds(got) == [50.0, 51.0, 52.0]
    assert asm.counters.late_parts == 0  # a latest value is never "late"


def test_vfr_hud_that_arrives_during_the_wait_for_the_actuator_report_is_used() -> None:
    asm = SampleAssembler(_map(), H, wait_s=0.02)
    for name, values in (
        ("ACTUATOR_OUTPUT_STATUS", act(0)),
        ("VFR_HUD", hud(50.0)),
        ("AOA_SSA", aoa(0)),
        ("ATTITUDE", att(0)),
    ):
        got = asm.add(name, values, "r", 0.0)
    assert [s.k for s in got] == [0]
    assert asm.add("AOA_SSA", aoa(1), "r", 1.0) == [] and asm.add("ATTITUDE", att(1), "r", 1.0) == []
    assert asm.add("VFR_HUD", hud(51.0), "r", 1.005) == []  # the sample is waiting for its report anyway
    got = asm.add("ACTUATOR_OUTPUT_STATUS", act(1), "r", 1.01)
    assert speeds(got) == [51.0]
    assert asm.add("AOA_SSA", aoa(2), "r", 2.0) == [] and asm.add("ATTITUDE", att(2), "r", 2.0) == []
    late = asm.poll(2.03)  # the report never came: the wait runs out, the held value serves
    assert [s.k for s in late] == [2] and speeds(late) == [51.0] and asm.counters.waited_out == 1


def test_a_held_value_older_than_its_hold_is_not_used_and_the_stream_can_resume() -> None:
    raw = _raw()
    raw["measured"]["airspeed"]["hold"] = 0.2  # 4 samples of the vehicle's clock
    asm = SampleAssembler(_map(raw), H)
    got = asm.add("VFR_HUD", hud(50.0), "r", 0.0)  # before any timed part: stamped with the first instant
    for k in range(10):  # VFR_HUD stops after k = 0
        got += asm.add("AOA_SSA", aoa(k), "r", 0.0)
        got += asm.add("ATTITUDE", att(k), "r", 0.0)
    assert [s.k for s in got] == [0, 1, 2, 3, 4]  # age 0 .. 0.2 s
    assert asm.missing_held() == ("VFR_HUD",)
    got = asm.add("VFR_HUD", hud(55.0), "r", 0.0)  # it comes back: the newest waiting sample goes
    assert [s.k for s in got] == [9] and speeds(got) == [55.0]
    assert asm.counters.held_missing == 4 and asm.counters.incomplete == 0  # k = 5..8, counted as what they lacked
    assert asm.missing_held() == ()


def test_observe_only_log_reordered_by_a_few_ms() -> None:
    """MAVProxy logs every message as it arrives; VFR_HUD of k landing after ACTUATOR_OUTPUT_STATUS of k."""
    asm = SampleAssembler(_map(), H, observe=True)
    got = asm.add("VFR_HUD", hud(49.0), "r", 0.0)
    for k in range(4):
        for name, values in (
            ("AOA_SSA", aoa(k)),
            ("ATTITUDE", att(k)),
            ("ACTUATOR_OUTPUT_STATUS", act(k)),
            ("VFR_HUD", hud(50.0 + k)),
        ):
            got += asm.add(name, values, "r", k * H + 0.001)
    assert [s.k for s in got] == [0, 1, 2, 3] and speeds(got) == [49.0, 50.0, 51.0, 52.0]


# --- the vehicle table: deviations in, absolute deflections out ---------------------------------------


def _table(tmp_path: Path, observe: bool = False) -> tuple[VehicleTable, object]:
    plant, gains = aircraft_files(tmp_path)
    model = load_model(plant, gains)
    return VehicleTable(Fleet(model), AlarmConfig(1.0, 0.5, 2), observe=observe), model


def _sample(table: VehicleTable, k: int, y_abs, elevator: float | None, now: float):
    alpha, q, theta, v = y_abs
    out = table.message(7, "VFR_HUD", hud(v), "r", now)
    if elevator is not None:
        out += table.message(7, "ACTUATOR_OUTPUT_STATUS", act(k, elevator), "r", now)
    out += table.message(7, "ATTITUDE", att(k, q, theta), "r", now)
    out += table.message(7, "AOA_SSA", aoa(k, alpha), "r", now)
    assert len(out) == 1, out
    vehicle, sample = out[0]
    return table.process(vehicle, sample, now, now)


def test_the_estimator_steps_in_deviations_and_the_command_is_absolute(tmp_path: Path) -> None:
    table, model = _table(tmp_path)
    assert model.estimator.u0 == [-4.3]
    ref = Estimator(model.plant, GAINS, u0=[U0])  # the same law, fed by hand with deviations
    s = ref.initial_state()
    rng = np.random.default_rng(0)
    elevator = U0
    for k in range(12):
        y_dev = rng.normal(0, [0.5, 2.0, 0.5, 1.0])
        y_abs = [float(np.float32(v)) for v in Y0 + y_dev]  # what the wire carries
        p = _sample(table, k, y_abs, elevator, float(k))
        # what the estimator got: the measured absolute values minus the operating point (q, theta via rad)
        measured = p.sample.values
        expect_y = [measured[n] - Y0[i] for i, n in enumerate(("alpha", "q", "theta", "airspeed"))]
        assert p.y == pytest.approx(expect_y, abs=1e-12)
        r = ref.step(s, k, expect_y, u_prev=[float(np.float32(elevator)) - U0])
        assert p.result.u == pytest.approx(r.u, abs=1e-12) and p.result.f_hat == pytest.approx(r.f_hat, abs=1e-12)
        assert p.u_abs == pytest.approx([U0 + float(r.u[0])], abs=1e-12)  # what goes on the wire
        assert p.command_applied in (None, True)
        elevator = p.u_abs[0]  # the vehicle applies it and reports it with the next sample
    assert table.counters.not_applied == 0 and table.counters.no_report == 0


@pytest.mark.parametrize("alpha_dev, absolute", [(200.0, -LIMIT), (-200.0, LIMIT)])
def test_saturation_holds_for_the_absolute_deflection(tmp_path: Path, alpha_dev: float, absolute: float) -> None:
    """K1 maps +-200 deg of alpha to about -+46 deg of elevator: the absolute command is clipped at +-25 deg,
    and the estimator steps with the clipped value as a deviation (-25 + 4.3 or 25 + 4.3)."""
    table, model = _table(tmp_path)
    p = _sample(table, 0, [OP["alpha"] + alpha_dev, 0.0, OP["theta"], OP["airspeed"]], U0, 0.0)
    assert p.u_abs == [absolute]
    assert p.result.u[0] == pytest.approx(absolute - U0)
    assert table.vehicles[7].state.u_prev[0] == pytest.approx(absolute - U0)  # the u(k-1) of its next step


def test_observe_only_reports_the_absolute_deflection_and_steps_with_its_deviation(tmp_path: Path) -> None:
    table, model = _table(tmp_path, observe=True)
    ref = Estimator(model.plant, GAINS, u0=[U0])
    s = ref.initial_state()
    for k, elevator in enumerate((-4.3, -5.3, -3.8)):
        p = _sample(table, k, [3.31, 1.0, 2.81, 52.4], elevator, float(k))
        r = ref.observe(s, k, [1.0, 1.0, 0.5, 1.0], [elevator - U0])
        assert p.u_abs == pytest.approx([elevator], abs=1e-6)  # float32 on the wire
        assert p.result.u == pytest.approx([elevator - U0], abs=1e-6)
        assert p.result.f_hat == pytest.approx(r.f_hat, abs=1e-5)


# --- offline: a telemetry log, the same rule by the log's record order ------------------------------------


def test_analyse_applies_the_same_rule_to_a_log(tmp_path: Path) -> None:
    """Observe-only log, one message per record, VFR_HUD of k written a few ms after the sample's other
    messages on even k and before them on odd k: each sample takes the VFR_HUD logged before its last part."""
    plant, gains = aircraft_files(tmp_path)
    model = load_model(plant, gains)
    codec = new_codec(3, 1)
    log = tmp_path / "flight.tlog"
    expected = {}
    held = None
    with TlogWriter(log) as w:
        for k in range(20):
            t_us, v = k * H_US, 50.0 + 0.25 * k
            timed = [
                mavlink.MAVLink_attitude_message(t_us // 1000, 0, 2.31 / DEG, 0, 0, 0.0, 0),
                mavlink.MAVLink_aoa_ssa_message(t_us, 2.31, 0.0),
                mavlink.MAVLink_actuator_output_status_message(t_us, 1, [-4.3] + [0.0] * 31),
            ]
            vfr = mavlink.MAVLink_vfr_hud_message(v, v, 90, 60, 100.0, 0.0)
            msgs = timed + [vfr] if k % 2 == 0 else [vfr] + timed
            if k % 2 == 1 or held is None:
                held = v
            expected[k] = held  # odd k: its own; even k: the previous sample's (its own came 3 ms later)
            if k % 2 == 0:
                held = v
            for i, m in enumerate(msgs):
                codec.send(m)
                w.write(1_700_000_000_000_000 + t_us + i * 3000, codec.file.take())
    result = analyse_log(log, Fleet(model), AlarmConfig(1.0, 0.5, 2))
    assert [r.k for r in result.records] == list(range(20))  # k = 0 waited for the log's first VFR_HUD
    for r in result.records:
        assert r.y[3] == pytest.approx(expected[r.k] - 51.4, abs=1e-5), r.k  # y is the deviation
        assert r.alpha == pytest.approx(2.31, abs=1e-6)  # the measured value is recorded as measured
        assert r.u == pytest.approx([0.0], abs=1e-6)  # the estimator's u(k): the deviation of -4.3


def test_a_missing_or_stopped_vfr_hud_is_named_in_a_warning(tmp_path: Path, caplog) -> None:
    table, _model = _table(tmp_path)
    for k in range(3):  # AOA_SSA and ATTITUDE only: the samples wait for an airspeed that never comes
        assert table.message(8, "AOA_SSA", aoa(k), "r", 0.0) == []
        assert table.message(8, "ATTITUDE", att(k), "r", 0.0) == []
    with caplog.at_level("WARNING", logger="monitor.service.vehicles"):
        assert table.warn_missing(10.0) == [8]
    assert (
        "vehicle sysid 8: telemetry arrives (AOA_SSA, ATTITUDE) but never becomes a sample: missing VFR_HUD"
        in caplog.text
    )
    caplog.clear()
    for k in range(3, 60):  # VFR_HUD for a while, then it stops: after 1 s of the vehicle's clock, samples drop
        now = 11.0 + k * H
        out = table.message(8, "AOA_SSA", aoa(k), "r", now)
        if k < 10:
            out += table.message(8, "VFR_HUD", hud(51.0), "r", now)
        out += table.message(8, "ATTITUDE", att(k), "r", now)
        for vehicle, sample in out:
            table.process(vehicle, sample, now, now)
    # the first VFR_HUD released the newest complete sample (k = 2; 0 and 1 dropped), k = 3..9 had their own
    # value, 10..29 the one of k = 9 (age <= 1 s); 30..59 wait for one, the oldest dropped beyond 16 pending
    assert table.vehicles[8].processed == 1 + 7 + 20
    assert table.assembly_totals()["held_missing"] == 2 + (30 - 16)
    with caplog.at_level("WARNING", logger="monitor.service.vehicles"):
        table.warn_missing(15.0)
    assert "vehicle sysid 8: 16 sample(s) dropped: VFR_HUD (no time field) not heard within its hold" in caplog.text
