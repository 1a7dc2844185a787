"""The demo's pieces without daemons: the Monte-Carlo's actuator, Fig. 5's steady state, the design list,
and a demo that survives a failed baseline design (the live run replaced by the same scenario simulated)."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from monitor.demo import montecarlo
from monitor.demo.live import Scenario
from monitor.demo.methods import METHODS, look
from monitor.demo.orchestrate import DemoOptions, Designed, Flown, run_demo
from monitor.demo.report import Row, format_table
from monitor.demo.steady import held_output_steady_state, q_caption
from monitor.design.result import DesignResult
from monitor.errors import DesignFailed, UserError, run_cli_command
from monitor.model import simulate as loop
from monitor.model.closed_loop import steady_state
from monitor.model.plant import Plant, load_plant
from monitor.wire.specs import parse_delay_spec, parse_fault_spec, parse_wind_spec
from tests.designs import designed


def _run(plant, gains, seed: int) -> loop.Trace:
    return loop.simulate(
        plant,
        gains,
        100,
        parse_fault_spec("bias:2@20"),
        parse_delay_spec("uniform:0:0.46", seed),
        parse_wind_spec("paper", plant.h, seed).values(),
    )


def test_monte_carlo_clips_the_elevator_as_the_live_vehicle_does():
    plant, result = designed("paper-continuous", "separate")
    assert plant.actuator.limit == 30.0
    for seed in range(3):
        trace = _run(plant, result.gains, seed)
        assert np.max(np.abs(trace.u)) == pytest.approx(30.0)  # the unstable loop swings between the limits
        assert np.max(np.abs(trace.alpha)) < 30.0  # bounded, comparable to the live run (12-15 deg), not 8e11
    free = dataclasses.replace(plant, actuator=dataclasses.replace(plant.actuator, limit=None))
    assert np.max(np.abs(_run(free, result.gains, 0).alpha)) > 1e6  # what an unlimited elevator would claim
    assert loop.actuator(plant, np.array([45.0]))[0] == 30.0


def test_monte_carlo_refuses_an_actuator_it_does_not_model():
    plant, result = designed("paper-continuous", "separate")
    slewing = dataclasses.replace(plant, actuator=dataclasses.replace(plant.actuator, rate_limit=60.0))
    with pytest.raises(UserError, match="rate-limited"):
        _run(slewing, result.gains, 0)


def test_fig5_pitch_rate_offset_is_the_plants_steady_state():
    plant, result = designed("paper-continuous", "certified")
    held = held_output_steady_state(plant, 2.0)
    assert held.x[0] == pytest.approx(0.0, abs=1e-12)
    assert held.x[1] == pytest.approx(-0.579, abs=5e-4) and held.u[0] == pytest.approx(-0.880, abs=5e-4)
    S_x, S_u = steady_state(plant, result.gains)  # the certified loop's own steady state agrees
    assert 2.0 * S_x[:, 0] == pytest.approx(held.x, abs=1e-6) and 2.0 * S_u[0, 0] == pytest.approx(held.u[0], abs=1e-6)
    caption, q = q_caption(plant, parse_fault_spec("bias:2@20"), 100)
    assert q == pytest.approx(held.x[1]) and "q = -0.58 deg/s" in caption and "u = -0.88 deg" in caption
    assert q_caption(plant, parse_fault_spec("ramp:0.1@20"), 100) == ("", None)  # no constant fault: no claim


def test_designs_are_one_list_and_any_name_gets_a_distinct_look():
    from monitor.demo.orchestrate import DemoOptions

    assert DemoOptions().methods == METHODS
    looks = [look(m) for m in METHODS]
    assert len({(s.colour, s.line) for s in looks}) == len(METHODS)
    assert look("some-future-design") not in looks


FIGURES = ("fig3_fault_estimate.png", "fig4_alpha.png", "fig5_q.png", "overview.png")
SHORT = Scenario(steps=40, fault="bias:2@10")


def _failing(*broken: str):
    """The project's designs (computed once per session), except that ``broken`` fail as on the issue's machine."""

    def design(method: str, plant: Plant) -> DesignResult:
        if method in broken:
            raise DesignFailed(f"{method} method, observer LMI: solver status optimal_inaccurate;\nno gains written")
        return designed(SHORT.plant, method)[1]

    return design


def _fly_in_simulation(d: Designed, scenario: Scenario, out: Path, progress) -> Flown:
    """The live run's stand-in: the same scenario simulated (no daemons, no sockets), scored the same way."""
    plant = load_plant(scenario.plant)
    trace, s = montecarlo.run_scenario(
        plant, d.gains.gains, scenario.steps, scenario.fault, scenario.delay, scenario.wind, scenario.seed
    )
    row = Row(
        d.method,
        d.stable,
        d.certificate,
        d.claim("gamma_e"),
        d.claim("gamma_z"),
        samples=int(trace.k.size),
        settling_steps=s.settling_steps,
        rms_ef=s.rms_ef,
        peak_alpha_after=s.peak_alpha_after,
        rms_alpha_after=s.rms_alpha_after,
        alarm_delay=None,
        false_alarms=0,
    )
    return Flown(row, trace, {"simulated": True})


def test_a_failed_baseline_design_is_a_row_and_the_demo_goes_on(tmp_path, capsys):
    options = DemoOptions(scenario=SHORT, out=str(tmp_path))
    assert run_demo(options, design=_failing("separate"), fly=_fly_in_simulation) == 0

    rows = {r["method"]: r for r in json.loads((tmp_path / "summary.json").read_text())["rows"]}
    assert list(rows) == list(METHODS)  # every design has its row, in the table's order
    failed = rows["separate"]
    assert failed["failure"] == (
        "design failed: separate method, observer LMI: solver status optimal_inaccurate; no gains written"
    )  # one line
    assert failed["stable"] is None and failed["samples"] is None  # no verdict, no run: nothing made up
    for m in ("certified", "robust-separate", "paper"):
        assert rows[m]["failure"] is None and rows[m]["stable"] is True and rows[m]["samples"] == SHORT.steps
    assert rows["certified"]["certificate"] == "valid"
    for name in FIGURES:
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (tmp_path / "gains" / "separate.toml").exists()  # a failed design writes no gains

    out, err = capsys.readouterr()
    assert "\nseparate         design failed: separate method, observer LMI" in out  # the table's row
    assert "Failed:     separate (no gains, no verdict, no run): design failed: separate method" in out
    assert "fault-monitor demo: WARNING: the separate baseline failed" in err


def test_a_failed_certified_design_fails_the_demo_after_writing_the_rest(tmp_path, capsys):
    options = DemoOptions(scenario=SHORT, out=str(tmp_path), methods=("certified", "separate"), runs=2)
    args = argparse.Namespace(command="demo", func=lambda _: run_demo(options, design=_failing("certified")))
    assert run_cli_command("fault-monitor", args) == DesignFailed.exit_code == 3  # as `fault-monitor design` exits

    results = json.loads((tmp_path / "montecarlo.json").read_text())["results"]
    assert results["certified"]["failure"].startswith("design failed: certified method")
    assert results["separate"]["runs"] == 2 and results["separate"]["stable"] is False  # the baseline still ran
    out, err = capsys.readouterr()
    assert "\ncertified       design failed: certified method" in out
    assert "fault-monitor demo: error: certified method, observer LMI: solver status optimal_inaccurate" in err


def test_a_failed_row_widens_no_column():
    ran = Row("certified", True, "valid", 2.24, 2.19, 100, 2, 0.316, 0.63, 0.153, 3, 0)
    alone = format_table([ran]).splitlines()
    table = format_table([ran, Row.failed("robust-separate", "design failed: " + "x" * 200)]).splitlines()
    assert len(table[1]) == len(alone[1]) + len("robust-separate") - len("certified")  # only the name column grew
    assert table[3] == "robust-separate  design failed: " + "x" * 200


def test_aircraft_rows_add_the_model_and_the_late_window():
    ran = Row(
        "certified",
        True,
        "valid",
        2.49,
        16.6,
        900,
        28,
        0.102,
        0.92,
        0.41,
        3,
        0,
        model="longitudinal",
        ef_late=0.00039,
        alpha_late=-0.002,
    )
    lines = format_table([ran, Row.failed("separate", "design failed: why", "short-period")]).splitlines()
    head = lines[0].split("  ")
    assert head[0].strip() == "model" and "|e_f| 30 s after, deg" in lines[0] and "alpha 30 s after, deg" in lines[0]
    assert lines[2].startswith("longitudinal  certified") and "0.00039" in lines[2] and "-0.002" in lines[2]
    assert lines[3].split() == ["short-period", "separate", "design", "failed:", "why"]
    assert "model" not in format_table([dataclasses.replace(ran, model=None)])  # the paper's table is unchanged


def test_late_window_is_the_second_ending_30_s_after_onset_and_none_when_the_run_is_shorter():
    from monitor.demo.report import late_window

    k = np.arange(0, 800)
    f = np.where(k >= 100, 2.0, 0.0)
    f_hat = f + np.where((k > 680) & (k <= 700), 0.5, 0.0)  # wrong only in the second ending at onset + 30 s
    alpha = np.where(k > 680, 0.25, 0.0)
    trace = montecarlo.Trace(k=k, f=f, f_hat=f_hat, alpha=alpha, q=alpha, u=alpha, tau=alpha, alarm=k > 100)
    assert late_window(trace, 100, 20.0) == (pytest.approx(0.5), pytest.approx(0.25))
    assert late_window(trace, 100, 20.0, late_s=40.0) == (None, None)
    assert late_window(trace, None, 20.0) == (None, None)
