"""The manoeuvres of a real flight, read with an envelope: ``sim-vehicle --aircraft c172p`` flies the example
manoeuvre mission (turns at 30, 45 and 60 deg of bank, a slow-down to 65 kt and back, a climb and a descent) on
its own autopilot, and ``analyse`` reads the log with the five-point envelope kept in ``tests/data``
(``c172p-envelope-turns*.toml``: 100 kt level, 45 and 60 deg turns, 80 and 65 kt; scheduled by airspeed and the
bank's load factor, the throttle a known input; made by ``benchmarks/mission_envelope.py`` from the example
identification mission) and with its 100-kt point alone. No fault, then a 2 deg bias from the middle of the
slow-down. Loopback only; every wait bounded."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from monitor.design.result import DesignResult
from monitor.gains import read_envelope_gains, write_gains
from monitor.model.plant import load_plant
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.offline import analyse_log
from tests.daemons import REPO
from tests.mission_logs import log_mission

pytestmark = [pytest.mark.slow, pytest.mark.daemons]

DATA = REPO / "tests" / "data"
ENVELOPE, GAINS = DATA / "c172p-envelope-turns.toml", DATA / "c172p-envelope-turns-gains.toml"
ONE = DATA / "c172p-turns-100kt.toml"
MISSION = REPO / "docs" / "examples" / "mission-manoeuvres.toml"
H = 0.05


def segments() -> dict[str, tuple[float, float]]:
    out, t = {}, 0.0
    for seg in tomllib.loads(MISSION.read_text())["segment"]:
        out[seg["name"]] = (t, t + float(seg["duration"]))
        t += float(seg["duration"])
    return out


def read(tlog: Path, plant: Path, gains: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t from the first sample, f_hat, alarm) per sample, as ``analyse`` reads the log with the default alarm."""
    records = analyse_log(tlog, Fleet(load_model(plant, gains)), AlarmConfig()).records
    k = np.array([r.k for r in records])
    return (k - k[0]) * H, np.array([r.f_hat[0] for r in records]), np.array([r.alarm for r in records])


def one_trim(tmp_path: Path) -> Path:
    """The envelope's 100-kt point alone (its own plant file, ``c172p-turns-100kt.toml``, which the envelope was
    assembled from), with its gains from the envelope's file: the one-trim model."""
    design = read_envelope_gains(GAINS).points["c172p-id-100"]
    gains = tmp_path / "one-gains.toml"
    write_gains(gains, DesignResult("certified", design.gains, 0.0, 0.0, 0.0, 0.0, 0.0), load_plant(ONE))
    return gains


def test_no_alarm_through_turns_and_a_change_of_speed_where_one_trim_alarms(tmp_path: Path) -> None:
    tlog = log_mission(tmp_path, MISSION)
    t, f_env, alarm_env = read(tlog, ENVELOPE, GAINS)
    t_one, f_one, alarm_one = read(tlog, ONE, one_trim(tmp_path))
    assert len(t) == len(t_one) >= 11000  # the whole 560-s flight, sample for sample
    seg = segments()
    for name, (a, b) in seg.items():
        sel = (t >= a) & (t < b)
        print(f"{name:<16} one trim {np.abs(f_one[sel]).max():.3f}  envelope {np.abs(f_env[sel]).max():.3f}")
    # the one-trim model reads the 60 deg turn and the slow-down as a fault: the manoeuvres matter
    assert alarm_one.any()
    a, b = seg["turn-60"]
    assert np.abs(f_one[(t >= a) & (t < b)]).max() > 1.0
    # the envelope: no alarm anywhere, and the turns within a few tenths of a degree (measured: 0.26, 0.21, 0.31)
    assert not alarm_env.any()
    assert np.abs(f_env).max() < 0.8  # measured 0.54, in the slow-down
    for name in ("turn-30", "turn-45-left", "turn-60"):
        a, b = seg[name]
        assert np.abs(f_env[(t >= a) & (t < b)]).max() < 0.45, name


def test_a_bias_from_the_middle_of_the_slow_down_is_detected_at_once_and_estimated(tmp_path: Path) -> None:
    a, b = segments()["slow-down"]
    onset = 0.5 * (a + b)  # 230 s: 65 kt not yet reached
    tlog = log_mission(tmp_path, MISSION, "--fault", f"bias:2@{round(onset / H)}", name="fault")
    t, f, alarm = read(tlog, ENVELOPE, GAINS)
    assert not alarm[t < onset].any()
    first = t[(t >= onset) & alarm]
    assert first.size and first[0] - onset <= 2.0  # measured 0.15 s
    after = t >= onset + 2.0
    print(f"after onset + 2 s: f_hat {f[after].min():.3f} .. {f[after].max():.3f}, mean {f[after].mean():.3f}")
    assert abs(f[after].mean() - 2.0) < 0.1  # measured 1.99
    assert np.abs(f[after] - 2.0).max() < 0.8  # measured 0.54: the manoeuvres' own error, not within 5 %
    assert alarm[after].all()
