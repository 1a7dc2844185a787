"""A delay of one to 2.4 samples, end to end: ``sim-vehicle`` and ``fault-monitor run`` as daemons on loopback.

The monitor runs the lagged plant (``docs/examples/paper-continuous-long-delay.toml``) with its certified gains;
the vehicle applies each command when it arrives, as many samples late as drawn. Judged on what crossed the
wire: the estimates and the truth, both read from the Zenoh bus, matched by sample index.
"""

from __future__ import annotations

from pathlib import Path

from tests.daemons import Daemon, free_udp_port, wait_for
from tests.e2e.test_monitor_paper import wait_ready, zenoh_bus

PLANT = str(Path(__file__).parents[2] / "docs" / "examples" / "paper-continuous-long-delay.toml")
STEPS, ONSET, BIAS = 60, 20, 2.0


def test_a_loop_whose_commands_act_one_to_two_samples_late_estimates_and_holds(tmp_path: Path) -> None:
    from monitor.gains import write_gains
    from tests.designs import designed

    plant, result = designed(PLANT, "certified")
    gains = tmp_path / "long-delay.toml"
    write_gains(gains, result, plant)
    port = free_udp_port()
    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        truth = bus.collect("uav/*/truth")
        monitor_args = ["run", "--plant", PLANT, "--gains", str(gains), "--mavlink", f"udpin:127.0.0.1:{port}",
                        "--zenoh-mode", "client", "--zenoh-connect", bus.endpoint, "--name", "long-delay"]
        with Daemon("monitor", monitor_args, tmp_path / "monitor.log") as monitor:
            wait_ready(monitor)
            vehicle_args = ["run", "--plant", "paper-continuous", "--delay", "uniform:1:2.4", "--fault",
                            f"bias:{BIAS:g}@{ONSET}", "--steps", str(STEPS), "--speedup", "20", "--seed", "5",
                            "--mavlink", f"udpout:127.0.0.1:{port}", "--zenoh-mode", "client", "--zenoh-connect",
                            bus.endpoint]
            with Daemon("sim_vehicle", vehicle_args, tmp_path / "vehicle.log") as vehicle:
                assert vehicle.wait(60) == 0, vehicle.log()
            wait_for(lambda: len(estimates) >= STEPS - 2, 10, what="the monitor's estimates")
        wait_for(lambda: len(truth) >= STEPS, 5, what="every sample's truth")
    by_k = {e["k"]: e for e in estimates}
    truths = {t["k"]: t for t in truth}
    assert len(by_k) >= STEPS - 2 and len(truths) == STEPS, sorted(set(range(STEPS)) - set(by_k))
    acted = [t["tau"] for t in truths.values() if t["tau"] is not None]
    assert len(acted) > 0.8 * STEPS and min(acted) >= 1.0 and max(acted) > 2.0, acted  # every one a sample or more late
    assert sum(t["in_force"] <= t["k"] - 2 for t in truths.values()) > 10  # often u(k-2) or older was in force
    errors = [abs(by_k[k]["f_hat"][0] - truths[k]["f"][0]) for k in range(ONSET + 6, STEPS) if k in by_k]
    assert max(errors) <= 0.05 * BIAS, max(errors)  # within 5 % of the fault from 6 samples after onset
    assert max(abs(by_k[k]["f_hat"][0]) for k in range(ONSET) if k in by_k) < 0.05 * BIAS  # nothing before it
    assert max(abs(t["x"][0]) for t in truths.values()) < 2.0  # the loop holds: alpha stays within 2 deg
