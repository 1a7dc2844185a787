"""``fault-monitor run`` options that so far had only unit tests, end to end with real daemons on loopback:

* ``--signing-key``: a signed vehicle and a monitor reading the same key file close the loop (samples
  processed, commands applied by the vehicle); a monitor with another key processes nothing (every sample
  counted as a bad signature) and the vehicle applies no command;
* ``--fleet`` alone (no ``--plant``/``--gains``): the listed system ids are served, an unlisted one is
  refused (no estimates, counted) while the others go on being served;
* ``--vehicle-timeout``: a vehicle silent for longer is forgotten, so a new run of the same system id
  starting again at k = 0 from a new socket gets a fresh estimator (not the restart rule, not "stale").

Same pattern as ``test_monitor_paper.py``: a Zenoh router session in the test, daemons as its clients.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
from pathlib import Path

from tests.daemons import Daemon, free_udp_port, wait_for
from tests.monitor_bus import monitor_daemon, processed_count, shed_count, sim_daemon, wait_ready, zenoh_bus

STEPS = 30
SPEEDUP = 20


def _summary_count(log: str, name: str) -> int:
    """One counter of the monitor's exit summary line (``stopped: samples processed N, ..., <name> N, ...``)."""
    match = re.search(rf"stopped: .*?\b{re.escape(name)} (\d+)", log)
    assert match, f"no '{name}' in the exit summary:\n{log[-2000:]}"
    return int(match.group(1))


def _stop(monitor: Daemon) -> str:
    """SIGTERM the monitor, expect exit 0, return its log (which then holds the exit summary)."""
    monitor.signal(signal.SIGTERM)
    assert monitor.wait(15) == 0, monitor.log()[-3000:]
    return monitor.log()


def _sim_summary(path: Path) -> dict:
    return json.loads(path.read_text())


def _by_sysid(estimates: list[dict]) -> dict[int, list[int]]:
    out: dict[int, list[int]] = {}
    for e in estimates:
        out.setdefault(e["sysid"], []).append(e["k"])
    return out


# -- 1. MAVLink 2 signing between the two daemons ----------------------------------------------------------------


def test_signed_link_closes_the_loop_and_a_wrong_key_processes_nothing(tmp_path: Path, gains_file: Path) -> None:
    """Two monitors side by side (one with the vehicle's key, one with another key), each with its own
    signed vehicle: run concurrently to keep the test short."""
    key = tmp_path / "key.hex"
    key.write_text(os.urandom(32).hex() + "\n")  # 64 hex digits
    other = tmp_path / "other.txt"
    other.write_text("not the vehicle's passphrase\n")  # a passphrase: SHA-256 of it, a different key
    good_port, bad_port = free_udp_port(), free_udp_port()
    good_json, bad_json = tmp_path / "good-sim.json", tmp_path / "bad-sim.json"
    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        with (
            monitor_daemon(tmp_path, gains_file, good_port, bus, "signed", "--signing-key", str(key)) as good,
            monitor_daemon(tmp_path, gains_file, bad_port, bus, "wrongkey", "--signing-key", str(other)) as bad,
        ):
            wait_ready(good)
            wait_ready(bad)
            with (
                sim_daemon(
                    tmp_path,
                    good_port,
                    bus,
                    1,
                    "--fault",
                    "bias:2@10",
                    "--signing-key",
                    str(key),
                    "--summary-json",
                    str(good_json),
                    steps=STEPS,
                    speedup=SPEEDUP,
                ) as sim_good,
                sim_daemon(
                    tmp_path,
                    bad_port,
                    bus,
                    2,
                    "--fault",
                    "bias:2@10",
                    "--signing-key",
                    str(key),
                    "--summary-json",
                    str(bad_json),
                    steps=STEPS,
                    speedup=SPEEDUP,
                ) as sim_bad,
            ):
                assert sim_good.wait(30) == 0, sim_good.log()
                assert sim_bad.wait(30) == 0, sim_bad.log()
            # every sample answered, or on a machine too busy to keep up at 20x, shed (at most two; counted)
            wait_for(lambda: len([e for e in estimates if e["sysid"] == 1]) >= STEPS - 2, 30, what="signed estimates")
            good_log, bad_log = _stop(good), _stop(bad)
            processed = processed_count(good_log)
            wait_for(lambda: len([e for e in estimates if e["sysid"] == 1]) >= processed, 10, what="every estimate")

    # same key: every sample processed and answered, the vehicle applied the (signed) commands
    shed = shed_count(good_log)
    assert processed + shed == STEPS and shed <= 2 and _summary_count(good_log, "bad signature") == 0, good_log
    assert _summary_count(good_log, "commands") == processed
    s = _sim_summary(good_json)
    assert s["samples"]["sent"] == STEPS
    assert s["commands"]["received"] == processed and s["commands"]["applied"] >= processed - 2, s
    assert s["packets"].get("rejected_signature", 0) == 0, s
    per = _by_sysid(estimates)
    assert len(per[1]) == processed and set(per[1]) <= set(range(STEPS))

    # another key: nothing processed, every sample a bad signature, no command sent, none applied
    assert processed_count(bad_log) == 0 and _summary_count(bad_log, "commands") == 0
    assert _summary_count(bad_log, "bad signature") >= STEPS, bad_log[-2000:]
    assert _summary_count(bad_log, "vehicles") == 0
    s = _sim_summary(bad_json)
    assert s["samples"]["sent"] == STEPS
    assert s["commands"].get("received", 0) == 0 and s["commands"].get("applied", 0) == 0, s
    assert s["samples"].get("applied", 0) == 0 and s["samples"]["lost"] == STEPS, s
    assert 2 not in per, "a wrongly signed vehicle was estimated"


# -- 2. --fleet alone: listed vehicles served, an unlisted one refused ---------------------------------------------


def test_fleet_serves_listed_vehicles_and_refuses_an_unlisted_one(tmp_path: Path, gains_file: Path) -> None:
    fleet_dir = tmp_path / "fleet"
    (fleet_dir / "gains").mkdir(parents=True)
    shutil.copy(gains_file, fleet_dir / "gains" / "certified.toml")
    fleet = fleet_dir / "fleet.toml"
    fleet.write_text(  # relative gains paths: relative to the fleet file, not to the monitor's cwd
        '[vehicle.1]\nplant = "paper-continuous"\ngains = "gains/certified.toml"\n\n'
        '[vehicle.2]\nplant = "paper-continuous"\ngains = "gains/certified.toml"\n'
    )
    port = free_udp_port()
    sim3_json = tmp_path / "sim3.json"
    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        args = [
            "run",
            "--fleet",
            str(fleet),
            "--mavlink",
            f"udpin:127.0.0.1:{port}",
            "--zenoh-mode",
            "client",
            "--zenoh-connect",
            bus.endpoint,
            "--name",
            "fleet",
        ]
        with Daemon("monitor", args, tmp_path / "fleet.log") as monitor:
            wait_ready(monitor)
            with (
                sim_daemon(tmp_path, port, bus, 3, "--summary-json", str(sim3_json), steps=STEPS, speedup=SPEEDUP) as c,
                sim_daemon(tmp_path, port, bus, 1, "--fault", "bias:2@10", steps=STEPS, speedup=SPEEDUP) as a,
                sim_daemon(
                    tmp_path, port, bus, 2, "--fault", "bias:-1@10", "--seed", "7", steps=STEPS, speedup=SPEEDUP
                ) as b,
            ):
                assert a.wait(30) == 0 and b.wait(30) == 0 and c.wait(30) == 0, (a.log(), b.log(), c.log())
            wait_for(lambda: len(estimates) >= 2 * STEPS, 30, what=f"{2 * STEPS} estimates")
            assert monitor.proc.poll() is None, "the monitor stopped serving"
            statuses = {key for key, _ in bus.query("uav/*/fault/status")}
            log = _stop(monitor)

    per = _by_sysid(estimates)
    assert set(per) == {1, 2}, f"estimates for {sorted(per)}"
    assert sorted(per[1]) == sorted(per[2]) == list(range(STEPS))
    assert statuses == {"uav/1/fault/status", "uav/2/fault/status"}
    assert processed_count(log) == 2 * STEPS
    assert _summary_count(log, "refused") == STEPS and _summary_count(log, "vehicles") == 2
    assert len(re.findall(r"refusing vehicle sysid 3\b", log)) == 1, "one log line for the refused vehicle"
    assert "Traceback" not in log
    s = _sim_summary(sim3_json)
    assert s["samples"]["sent"] == STEPS and s["commands"].get("received", 0) == 0, s


# -- 3. --vehicle-timeout: a silent vehicle is forgotten -----------------------------------------------------------


def test_silent_vehicle_is_forgotten_after_the_timeout(tmp_path: Path, gains_file: Path) -> None:
    timeout = 1.0
    port = free_udp_port()
    with zenoh_bus() as bus:
        estimates = bus.collect("uav/*/fault/estimate")
        with monitor_daemon(tmp_path, gains_file, port, bus, "timeout", "--vehicle-timeout", str(timeout)) as monitor:
            wait_ready(monitor)
            with sim_daemon(tmp_path, port, bus, 5, "--fault", "bias:2@10", steps=STEPS, speedup=SPEEDUP) as first:
                assert first.wait(30) == 0, first.log()
            wait_for(lambda: len(estimates) >= STEPS, 30, what="first run's estimates")
            # housekeeping runs about once a second: forgotten within timeout + ~1 s (bounded generously)
            wait_for(
                lambda: "vehicle sysid 5 silent for" in monitor.log(),
                timeout + 5,
                what="the silent vehicle to be dropped",
            )
            first_run = list(estimates)
            with sim_daemon(
                tmp_path, port, bus, 5, "--fault", "bias:-1@5", "--seed", "9", steps=STEPS, speedup=SPEEDUP
            ) as second:  # a new process: a new ephemeral source port
                assert second.wait(30) == 0, second.log()
            wait_for(lambda: len(estimates) >= 2 * STEPS, 30, what="second run's estimates")
            log = _stop(monitor)

    second_run = estimates[len(first_run) :]
    assert sorted(e["k"] for e in first_run) == list(range(STEPS))
    assert sorted(e["k"] for e in second_run) == list(range(STEPS)), "the new run was not estimated from k = 0"
    # a fresh estimator: the second run's estimate converges to its own fault, with nothing of the first's
    assert min(second_run, key=lambda e: e["k"])["k"] == 0
    assert abs(max(second_run, key=lambda e: e["k"])["f_hat"][0] - (-1.0)) < 0.1
    assert processed_count(log) == 2 * STEPS
    assert _summary_count(log, "stale") == 0 and _summary_count(log, "duplicates") == 0
    # forgotten by the timeout (a new vehicle), not by the restart rule
    assert _summary_count(log, "vehicles") == 2 and _summary_count(log, "restarts") == 0
    assert len(re.findall(r"vehicle sysid 5 from .*: new estimator", log)) == 2
