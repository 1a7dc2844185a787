"""From a flight log to certified gains with the installed commands: ``fault-monitor identify`` on a c172p flight
(JSBSim, logged as MAVProxy logs), then ``fault-monitor design`` and ``verify`` on the plant file it wrote, as is.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib

from monitor.model.plant import load_plant
from tests.c172p_flights import fly, write_tlog


def _cli(*argv: str, timeout: float = 150.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor", *argv], capture_output=True, text=True, timeout=timeout)


def test_identify_writes_a_plant_the_chain_takes_as_it_is(tmp_path) -> None:
    """On a log written here (not by sim-vehicle); design and verify on such a plant:
    tests/e2e/test_aircraft_chain.py."""
    log, plant_file = tmp_path / "c172p.tlog", tmp_path / "c172p.toml"
    write_tlog(log, fly())

    proc = _cli("identify", str(log), "--out", str(plant_file))
    assert proc.returncode == 0, proc.stderr
    assert "fit on held-out data" in proc.stdout and "short period" in proc.stdout and "phugoid" in proc.stdout
    assert "Traceback" not in proc.stderr
    plant = load_plant(plant_file)
    assert plant.n == 4 and tomllib.loads(plant_file.read_text())["identification"]["model"] == "longitudinal"
    assert plant.signals is not None and set(plant.signals["operating_point"]) == {
        "alpha",
        "q",
        "theta",
        "airspeed",
        "elevator",
    }


def test_identify_refusals_are_one_line_and_exit_2(tmp_path) -> None:
    log = tmp_path / "trim.tlog"
    write_tlog(log, fly(seconds=0.0, lead_in=15.0))
    proc = _cli("identify", str(log), "--out", str(tmp_path / "p.toml"))
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "no excitation" in proc.stderr, proc.stderr
    proc = _cli("identify", str(tmp_path / "nothing.tlog"), "--out", str(tmp_path / "p.toml"))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "no such log file" in proc.stderr
    assert not (tmp_path / "p.toml").exists()
