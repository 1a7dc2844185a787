"""A derived angle of attack live: ``fault-monitor run --observe`` fed over UDP by an autopilot without an AoA
vane (ATTITUDE, LOCAL_POSITION_NED, WIND_COV, ACTUATOR_OUTPUT_STATUS of a c172p flown by JSBSim in a crosswind and
light turbulence, ``tests/px4_flight.py``), its signal map deriving α; the recording's α against JSBSim's own."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np

from tests.daemons import Daemon, free_udp_port, wait_for
from tests.derived_maps import MAVLINK_MAP
from tests.px4_flight import T0_US, H, fly, mavlink_samples


def test_run_observe_derives_alpha_from_velocity_attitude_and_wind(tmp_path: Path) -> None:
    from monitor.service.recording_reader import load_recording
    from tests.gains_files import hand_made_gains_file, paper_plant_sampled_at
    from tests.monitor_bus import processed_count, wait_ready, zenoh_bus

    flight = fly(3.0, lead_in=0.5, wind_ned_fps=(15.0, -20.0, 0.0), turbulence="light")
    plant = paper_plant_sampled_at(tmp_path / "plant.toml", H)
    gains = hand_made_gains_file(tmp_path / "gains.toml", str(plant))
    (tmp_path / "map.toml").write_text(MAVLINK_MAP)
    port, rrd = free_udp_port(), tmp_path / "run.rrd"
    with zenoh_bus() as bus:
        args = [
            "run",
            "--observe",
            "--plant",
            str(plant),
            "--gains",
            str(gains),
            "--signals",
            str(tmp_path / "map.toml"),
        ]
        args += ["--mavlink", f"udpin:127.0.0.1:{port}", "--rrd", str(rrd), "--no-truth", "--no-gcs-feedback"]
        args += ["--zenoh-mode", "client", "--zenoh-connect", bus.endpoint, "--name", "derived"]
        estimates = bus.collect("uav/*/fault/estimate")
        with Daemon("monitor", args, tmp_path / "monitor.log") as monitor:
            wait_ready(monitor)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                for i, (_t, frames) in enumerate(mavlink_samples(flight)):
                    for frame in frames:  # one message per datagram, as a router forwards them
                        sock.sendto(frame, ("127.0.0.1", port))
                    # paced by the monitor's estimates, at most three samples ahead: a sample waits for at most
                    # two before it (not past its deadline of h = 20 ms, however slow the machine), and the test
                    # does not hang on a sample the monitor leaves out (the first, before the derivation has wind)
                    wait_for(lambda i=i: len(estimates) >= i - 2, 10, interval=0.001, what=f"the estimate of {i - 2}")
            wait_for(lambda: len(estimates) >= len(flight) - 2, 10, what="the last samples' estimates")
            assert monitor.stop() == 0, monitor.log()[-2000:]
            log = monitor.log()
    assert "y0=angle_of_attack(velocity_ned, attitude_euler, wind_ned)" in log, log[-2000:]
    processed = processed_count(log)
    assert processed >= len(flight) - 2, log[-2000:]
    samples = load_recording(rrd).vehicles[1].samples
    assert len(samples) == processed
    ks = [round((s.t * 1e6 - T0_US) / (H * 1e6)) for s in samples]
    alpha = np.array([s.alpha for s in samples])
    assert np.max(np.abs(alpha - flight.alpha[ks])) < 2e-4  # float32 on the wire
    assert np.ptp(alpha) > 1.0
