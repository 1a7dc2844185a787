"""``sim-vehicle run --aircraft c172p --mission FILE`` as a real daemon: the short example mission read back from its
truth file, a compensation sent over MAVLink and reported back in ACTUATOR_OUTPUT_STATUS, and a segment the
aircraft cannot fly ending the run with one line. Loopback only; every wait bounded; every process stopped."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from monitor.wire.mavlink import MONITOR_COMPONENT, Command, encode_command, new_codec, sample_index
from tests.daemons import REPO, Daemon, free_udp_port

H = 0.05
SHORT = REPO / "docs" / "examples" / "mission-short.toml"


def vehicle(tmp_path: Path, port: int, *args: str) -> Daemon:
    return Daemon(
        "sim_vehicle",
        ["run", "--aircraft", "c172p", "--mavlink", f"udpout:127.0.0.1:{port}", "--no-zenoh", *args],
        tmp_path / "vehicle.log",
    )


def read_jsonl(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


@pytest.mark.not_paced  # as fast as JSBSim goes: no pace
def test_the_short_example_mission_is_flown_segment_by_segment_as_commanded(tmp_path: Path) -> None:
    truth_file, summary = tmp_path / "truth.jsonl", tmp_path / "summary.json"
    with vehicle(
        tmp_path,
        free_udp_port(),
        "--mission",
        str(SHORT),
        "--speedup",
        "1e4",
        "--truth-jsonl",
        str(truth_file),
        "--summary-json",
        str(summary),
    ) as d:
        assert d.wait(60) == 0, d.log()[-3000:]
    truth = read_jsonl(truth_file)
    assert [t["k"] for t in truth] == list(range(1500))  # 75 s at 20 Hz: the run lasts the mission
    order = [t["segment"] for t in truth]
    assert [s for i, s in enumerate(order) if i == 0 or s != order[i - 1]] == ["level", "turn-45", "slow-down"]
    assert order.count("level") == 200 and order.count("turn-45") == 600 and order.count("slow-down") == 700

    def during(name: str, after: float) -> list[dict]:
        rows = [t for t in truth if t["segment"] == name]
        return [t for t in rows if t["t"] >= rows[0]["t"] + after]

    bank = np.array([t["bank_deg"] for t in during("turn-45", 8.0)])  # rolled in at 10 deg/s, then settled
    assert np.abs(bank - 45.0).max() < 3.0, (bank.min(), bank.max())
    assert np.abs([t["bank_deg"] for t in during("slow-down", 10.0)]).max() < 3.0  # rolled out
    assert all(abs(t["airspeed_kt"] - 100.0) < 3.0 for t in during("level", 0.0) + during("turn-45", 0.0))
    assert abs(truth[-1]["airspeed_kt"] - 90.0) < 3.0 and truth[-1]["reference"]["airspeed_kt"] == 90.0
    assert max(abs(t["altitude_ft"] - 3000.0) for t in truth) < 100.0
    load = np.array([t["load_factor"] for t in during("turn-45", 10.0)])
    assert load.mean() == pytest.approx(2**0.5, rel=0.05)  # 1/cos(45 deg) in a level turn
    s = json.loads(summary.read_text())
    assert s["samples"]["onboard"] == 1500 and s["commands"].get("received", 0) == 0


def test_a_compensation_sent_over_mavlink_is_added_after_its_delay_and_reported(tmp_path: Path) -> None:
    plan = tmp_path / "level.toml"
    plan.write_text('[[segment]]\nname = "level"\nduration = 4\nairspeed = 100\naltitude = 3000\nbank = 0\n')
    port = free_udp_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    codec, parser = new_codec(255, MONITOR_COMPONENT), new_codec(255, MONITOR_COMPONENT)
    per_k: dict[int, dict] = {}
    truth_file = tmp_path / "truth.jsonl"
    try:
        with vehicle(
            tmp_path,
            port,
            "--mission",
            str(plan),
            "--compensation",
            "--speedup",
            "10",
            "--delay",
            "const:0.02",
            "--truth-jsonl",
            str(truth_file),
        ) as d:
            rx.settimeout(0.2)
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                try:
                    data, src = rx.recvfrom(65535)
                except TimeoutError:
                    if d.proc is not None and d.proc.poll() is not None:
                        break
                    continue
                msgs = {m.get_type(): m for m in parser.parse_buffer(data) or []}
                if "AOA_SSA" in msgs:
                    k = sample_index(msgs["AOA_SSA"].time_usec, H)
                    per_k[k] = msgs
                    if k >= 20:  # from sample 20 on, a compensation of +1 deg answers every sample
                        rx.sendto(encode_command(codec, Command(1, k, 1.0), H), src)
            assert d.wait(20) == 0, d.log()[-3000:]
    finally:
        rx.close()
    assert sorted(per_k) == list(range(80))
    out = {k: msgs["ACTUATOR_OUTPUT_STATUS"].actuator[:3] for k, msgs in per_k.items()}
    assert all(out[k][2] == 0.0 and out[k][0] == pytest.approx(out[k][1], abs=1e-5) for k in range(21))
    applied = [k for k in range(21, 80) if out[k][2] == pytest.approx(1.0)]
    assert len(applied) >= 50, out  # a few answers may arrive late at 10x over loopback: held, still 1 deg
    assert all(out[k][0] == pytest.approx(out[k][1] + 1.0, abs=1e-5) for k in applied)  # applied = autopilot + 1
    truth = read_jsonl(truth_file)
    acted = [t for t in truth if t["tau"] is not None]
    assert acted and all(t["tau"] >= 0.02 - 1e-9 for t in acted)  # after the drawn delay, never before
    assert truth[-1]["compensation"] == pytest.approx(1.0, abs=1e-6)  # controls[1] x 30 deg, a float32 on the wire
    assert "ignored while flying on board (autopilot/excitation) 0" in d.log()


@pytest.mark.not_paced  # as fast as JSBSim goes: no pace
def test_a_segment_the_aircraft_cannot_fly_ends_the_run_with_one_line(tmp_path: Path) -> None:
    plan = tmp_path / "fast.toml"
    plan.write_text(
        '[[segment]]\nname = "level"\nduration = 2\nairspeed = 100\naltitude = 3000\nbank = 0\n'
        '[[segment]]\nname = "fast"\nduration = 120\nairspeed = 140\naltitude = 3000\nbank = 0\n'
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    proc = subprocess.run(
        [sys.executable, "-m", "sim_vehicle", "--log-level", "warning", "run", "--aircraft", "c172p"]
        + [
            "--mission",
            str(plan),
            "--speedup",
            "1e5",
            "--no-zenoh",
            "--mavlink",
            f"udpout:127.0.0.1:{free_udp_port()}",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
        env=env,
    )
    assert proc.returncode == 3, proc.stderr  # as any flight that cannot go on (a crash): summary, one line
    assert proc.stdout.startswith("sim-vehicle summary")
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("sim-vehicle run: error: c172p: cannot hold 140 kt in segment 'fast' at t = ")
    assert "throttle at full for 5 s" in lines[0]
