"""`fault-monitor margin`: every point of the answer is certified, and the margin is where certificates stop."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import resources

import pytest

from monitor.checks.verify import verify_gains
from monitor.gains import read_gains
from monitor.model.plant import load_plant, with_tau_max

UNSTABLE_PLANT = """
form = "continuous"
name = "unstable-pitch"
h = 1.0
tau_min = 0.0
tau_max = 0.2
A_c = [[0.6, 1.0], [0.0, -3.0]]   # an unstable mode: the delay the loop can take is finite
B_c = [[0.0], [2.0]]
D_cf = [[0.0], [1.0]]
D_cd = [[0.5], [1.0]]
C = [[1.0, 0.0]]
"""


@pytest.fixture(scope="module")
def margin_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("margin")
    (d / "plant.toml").write_text(UNSTABLE_PLANT)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "margin",
            "--plant",
            str(d / "plant.toml"),
            "--json",
            "--tolerance",
            "0.02",
            "--points",
            "3",
            "--out",
            str(d / "gains.toml"),
            "--png",
            str(d / "margin.png"),
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr
    return d, json.loads(proc.stdout), proc.stderr


def test_margin_json_has_the_contract_shape(margin_run):
    _, doc, stderr = margin_run
    assert 0.0 < doc["tau_max"] < 1.0
    assert doc["curve"] and all(set(p) >= {"tau_max", "gamma_e"} for p in doc["curve"])
    taus = [p["tau_max"] for p in doc["curve"]]
    assert taus == sorted(taus) and taus[-1] == pytest.approx(doc["tau_max"])
    assert "tau_max =" in stderr  # bisection progress on stderr, JSON alone on stdout


def test_gains_at_the_margin_are_stable_over_the_whole_interval_and_a_wider_one_has_no_certificate(margin_run):
    d, doc, _ = margin_run
    plant = load_plant(d / "plant.toml")
    at_margin = with_tau_max(plant, doc["tau_max"])
    gf = read_gains(d / "gains.toml")
    assert gf.meta["plant_hash"] == at_margin.digest  # designed for the plant with that tau_max
    v = verify_gains(at_margin, gf.gains, gf.certificate, gf.meta["gamma_e"], gf.meta["gamma_z"])
    assert v.stable and v.certificate_valid is True
    assert (d / "margin.png").stat().st_size > 1000


def test_beyond_the_margin_the_design_finds_no_certificate(margin_run):
    """The bisection's own failed probe lies within the tolerance above the margin (0.02 s here).

    Beyond the margin of the objective margin used (fast, its default), that objective finds no certificate.
    The default design (no objective named) would fall back to the H-infinity objective there, whose own
    margin may be wider: the margin is per objective, as `margin --objective` says.
    """
    _, doc, _ = margin_run
    assert doc["objective"] == "fast"
    assert doc["no_certificate_at"] is not None
    assert doc["tau_max"] < doc["no_certificate_at"] <= doc["tau_max"] + 0.02 + 1e-12


def test_gamma_e_grows_with_the_delay_interval(margin_run):
    _, doc, _ = margin_run
    gammas = [p["gamma_e"] for p in doc["curve"]]
    assert gammas[-1] > gammas[0]


def test_with_tau_max_is_what_a_plant_file_with_that_bound_gives(tmp_path):
    plant = load_plant("paper-continuous")
    variant = with_tau_max(plant, 0.3)
    edited = tmp_path / "p.toml"
    text = resources.files("monitor.presets").joinpath("paper-continuous.toml").read_text("utf-8")
    edited.write_text(text.replace("tau_max = 0.4612", "tau_max = 0.3"))
    from_file = load_plant(edited)
    assert from_file.digest == variant.digest and from_file.tau_bar == variant.tau_bar
    assert (from_file.B0 == variant.B0).all()
