"""The vehicle's event logic (sim_vehicle/simulation.py) without sockets: a test-side controller answers.

The closed loop is checked against the paper's discrete model (2) evaluated with the true tau(k) that the
truth stream reports, which is exact when the input is piecewise constant as the simulator makes it.
"""

from __future__ import annotations

import numpy as np
import pytest

from monitor.model.discretize import discretize
from monitor.model.plant import load_plant
from monitor.wire.specs import Wind, parse_delay_spec, parse_fault_spec
from sim_vehicle.network import DOWNLINK, UPLINK, Impairment
from sim_vehicle.simulation import Simulation
from tests.sim_recorder import Recorder

PLANT = load_plant("paper-continuous")


def fly(sim: Simulation, rec: Recorder, gain: float = 0.5, latency: float = 0.0, answer=None) -> None:
    """Run to the end; every delivered sample is answered ``latency`` after it left, with u = -gain * alpha."""
    answers: list[tuple[float, int, float]] = []
    while not sim.done:
        t_next = sim.next_time()
        due = [a for a in answers if a[0] <= t_next]
        if due:
            t_arr, k, u = min(due)
            answers.remove((t_arr, k, u))
            sim.run_until(t_arr)
            sim.receive_command(k, u, t_arr)
            continue
        sim.run_until(t_next)  # only the events at t_next: the samples in rec were sent at t_next
        for s in rec.samples:
            if answer is None or answer(s.k):
                answers.append((t_next + latency, s.k, -gain * s.alpha_deg))
        rec.samples.clear()


def predict(truth: list[dict], fault, gain: float) -> np.ndarray:
    """x(k+1) from model (2) with the reported tau(k), u(k) = -gain * alpha(k), held when not applied."""
    xs = [np.array(truth[0]["x"])]
    u_prev = 0.0
    for row in truth[:-1]:
        x = xs[-1]
        u = -gain * x[0] if row["tau"] is not None else u_prev
        D = discretize(PLANT.continuous, PLANT.h, row["tau"] if row["tau"] is not None else 0.0)
        xs.append(
            D.A @ x + D.B0[:, 0] * u + D.B1[:, 0] * u_prev + D.Df[:, 0] * fault.f(row["k"]) + D.Dd[:, 0] * row["d"][0]
        )
        u_prev = u
    return np.array(xs)


def test_closed_loop_matches_the_discrete_model_with_the_true_delay():
    rec = Recorder()
    fault = parse_fault_spec("bias:2@5")
    sim = Simulation(PLANT, rec, steps=25, fault=fault, delay=parse_delay_spec("uniform:0:0.46", seed=3), x0=[1.0, 0.0])
    fly(sim, rec, gain=0.5)
    truth = rec.truth
    assert [t["k"] for t in truth] == list(range(25)) and all(t["status"] == "applied" for t in truth)
    assert [t["tau"] for t in truth] == pytest.approx([t["tau_drawn"] for t in truth], abs=1e-12)
    assert np.allclose(np.array([t["x"] for t in truth]), predict(truth, fault, 0.5), atol=1e-9)
    assert rec.heartbeats == 25  # 1 Hz in simulated time, the first at t = 0
    assert [t["f"] for t in truth[4:6]] == [[0.0], [2.0]]


def test_slow_path_overruns_the_budget_and_the_true_tau_says_so():
    rec = Recorder()
    sim = Simulation(PLANT, rec, steps=10, delay=parse_delay_spec("const:0.2"), delay_split=0.5)
    fly(sim, rec, latency=0.25)  # the sample leaves at 0.1, the answer arrives at 0.35 > 0.2
    assert all(t["tau"] == pytest.approx(0.35) for t in rec.truth)


def test_commands_due_after_the_next_instant_are_late_and_the_actuator_holds():
    rec = Recorder()
    sim = Simulation(PLANT, rec, steps=6, delay=parse_delay_spec("const:1.2"), delay_split=0.5)
    fly(sim, rec)  # the answer is there at k h + 0.6, but tau = 1.2 >= h: late
    assert {t["status"] for t in rec.truth} == {"late"} and all(t["tau"] is None for t in rec.truth)
    assert sim.stats.commands["late"] == 6 and sim.stats.commands["applied"] == 0
    assert all(t["elevator"] == 0.0 for t in rec.truth)


def test_commands_arriving_after_the_next_instant_leave_their_sample_lost():
    rec = Recorder()
    sim = Simulation(PLANT, rec, steps=6, delay=parse_delay_spec("const:0.9"), delay_split=0.5)
    fly(sim, rec, latency=0.6)  # arrives at k h + 1.05, after the sample was settled
    assert {t["status"] for t in rec.truth} == {"lost"}
    assert sim.stats.commands["late"] == 5 and sim.stats.commands["applied"] == 0  # the last is never sent back


def test_unanswered_samples_are_lost_and_stale_or_future_commands_rejected():
    rec = Recorder()
    sim = Simulation(PLANT, rec, steps=8, delay=parse_delay_spec("const:0.1"))
    fly(sim, rec, answer=lambda k: k % 2 == 0)
    status = [t["status"] for t in rec.truth]
    assert status == ["applied", "lost"] * 4
    assert sim.receive_command(2, 1.0, sim.airframe.t) == "stale"
    assert sim.receive_command(99, 1.0, sim.airframe.t) == "future"


def test_duplicate_commands_are_applied_once():
    rec = Recorder()
    sim = Simulation(PLANT, rec, steps=3, delay=parse_delay_spec("const:0.1"))
    sim.run_until(0.05)
    assert sim.receive_command(0, 1.0, 0.05) == "scheduled"
    assert sim.receive_command(0, 1.0, 0.06) == "scheduled"
    sim.run_until(0.5)
    assert sim.stats.commands["applied"] == 1 and sim.stats.commands["stale"] == 1
    assert sim.receive_command(0, 1.0, 0.5) == "stale"


def test_link_statistics_match_the_requested_probabilities():
    imp = Impairment(loss=0.1, duplicate=0.05, reorder=0.03, seed=7)
    n = 20000
    fates = [imp.fate(UPLINK, k) for k in range(n)]
    assert np.mean([not f for f in fates]) == pytest.approx(0.1, abs=0.01)
    delivered = [f for f in fates if f]
    assert np.mean([len(f) == 2 for f in delivered]) == pytest.approx(0.05, abs=0.006)
    assert np.mean([f[0][1] == "reordered" for f in delivered]) == pytest.approx(0.03, abs=0.005)
    assert all(1.0 <= f[0][0] <= 1.5 for f in delivered if f[0][1] == "reordered")
    up = np.array([not imp.fate(UPLINK, k) for k in range(n)])
    down = np.array([not imp.fate(DOWNLINK, k) for k in range(n)])
    assert np.mean(up & down) == pytest.approx(0.01, abs=0.003)  # the two directions are independent


def test_lossy_run_counts_add_up_and_is_reproducible():
    def run():
        rec = Recorder()
        sim = Simulation(
            PLANT,
            rec,
            steps=300,
            impairment=Impairment(loss=0.2, duplicate=0.1, reorder=0.05, seed=1),
            delay=parse_delay_spec("uniform:0:0.46", seed=1),
        )
        fly(sim, rec)
        return sim, rec

    sim, rec = run()
    s, c = sim.stats.samples, sim.stats.commands
    assert s["taken"] == 300 and s["applied"] + s["late"] + s["lost"] == 300
    assert s["sent"] == 300 - s["dropped"] + s["duplicated"]
    # a sample is answered only if it got up and its command got down: about (1 - 0.2)^2 minus reordering
    assert s["applied"] / 300 == pytest.approx(0.8 * 0.8 * 0.95, abs=0.07)
    assert c["applied"] == s["applied"]
    sim2, rec2 = run()
    assert [t["x"] for t in rec2.truth] == [t["x"] for t in rec.truth]


def test_paper_wind_and_faults_reach_the_truth():
    rec = Recorder()
    sim = Simulation(
        PLANT,
        rec,
        steps=40,
        fault=parse_fault_spec("stuck:3@10+loe:0.5@20-30"),
        wind=Wind(),
        delay=parse_delay_spec("const:0.1"),
    )
    fly(sim, rec)
    t = rec.truth
    assert t[0]["d"] == [pytest.approx(0.001)] and t[1]["d"] == [pytest.approx(0.1 * 0.9922 * 0.01)]
    assert all(r["elevator"] == 3.0 and r["stuck"] for r in t[10:])
    assert [r["effectiveness"] for r in t[19:21] + t[29:31]] == [1.0, 0.5, 0.5, 1.0]


def test_autopilot_reports_its_own_command_and_applies_it_after_the_drawn_delay() -> None:
    rec = Recorder()
    sim = Simulation(
        PLANT,
        rec,
        steps=30,
        fault=parse_fault_spec("bias:2@10"),
        delay=parse_delay_spec("uniform:0:0.4", seed=3),
        autopilot=np.array([[-0.3]]),
    )
    while not sim.done:
        sim.run_until(sim.next_time())
        assert sim.receive_command(max(sim.k, 0), 25.0, sim.next_time() or 0.0) == "ignored_autopilot"
    assert len(rec.samples) == 30
    for s in rec.samples:  # u(k) = K y(k), reported with sample k
        assert s.elevator_deg == pytest.approx(-0.3 * s.alpha_deg, abs=1e-12)
    assert any(abs(s.elevator_deg) > 0.1 for s in rec.samples[12:])  # it reacts to the fault
    applied = [t for t in rec.truth if t["status"] == "applied"]
    assert len(applied) == 30 and all(0.0 <= t["tau"] <= 0.4 + 1e-9 for t in applied)
    assert [t["tau"] for t in applied[:5]] == pytest.approx([t["tau_drawn"] for t in applied[:5]])


def test_an_autopilot_flight_counts_its_samples_as_flown_on_board_not_answered():
    rec = Recorder()
    sim = Simulation(
        PLANT, rec, steps=40, delay=parse_delay_spec("uniform:0:0.46", seed=2), autopilot=np.array([[-0.5]])
    )
    fly(sim, rec)  # the test-side controller answers too: the vehicle ignores it while it flies itself
    s, c = sim.stats.samples, sim.stats.commands
    assert s["onboard"] == 40 and s["applied"] == 0 and s["late"] == 0 and s["lost"] == 0
    assert c["received"] == c["ignored_autopilot"] > 0 and c["applied"] == 0
    summary = sim.stats.summary()
    assert "answered in time 0" in summary and "flown on board (autopilot/excitation) 40" in summary
