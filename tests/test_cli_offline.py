"""`fault-monitor design` and `verify` as a user runs them: files, exit codes, JSON."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import pytest


def fm(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor", *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def certified_gains(tmp_path_factory):
    out = tmp_path_factory.mktemp("g") / "certified.toml"
    proc = fm("design", "--plant", "paper", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out


def test_design_writes_a_contract_gains_file(certified_gains):
    doc = tomllib.loads(certified_gains.read_text())
    g = doc["gains"]
    assert g["method"] == "certified" and g["plant_hash"].startswith("sha256:")
    assert len(g["L"]) == 2 and len(g["L"][0]) == 1 and len(g["K3"]) == 1
    assert g["objective"] == "fast"  # the default certified design
    assert g["gamma_e"] <= 2.4 and doc["solver"]["status"] == "optimal"
    assert {"P", "Q", "vertices"} <= set(doc["certificate"])


def test_verify_json_agrees_with_the_design(certified_gains):
    proc = fm("verify", "--plant", "paper", "--gains", str(certified_gains), "--json")
    assert proc.returncode == 0, proc.stderr
    v = json.loads(proc.stdout)
    assert v["stable"] is True and v["certificate_valid"] is True
    assert {"stable", "rho_max", "tau_worst", "hinf_ef", "hinf_y"} <= set(v)
    assert v["hinf_ef"] <= json.loads(json.dumps(tomllib.loads(certified_gains.read_text())["gains"]["gamma_e"])) * (
        1 + 1e-6
    )


def test_verify_exits_nonzero_for_the_published_gains():
    proc = fm("verify", "--plant", "paper", "--L", "0.0124,-0.0008", "--M", "0.8486", "--K1", "-11.2657", "--json")
    assert proc.returncode == 1
    assert json.loads(proc.stdout)["stable"] is False


def test_failed_design_leaves_no_file(tmp_path):
    plant = tmp_path / "unobservable.toml"
    plant.write_text(
        'form="discrete"\nh=1.0\ntau_min=0.0\ntau_max=0.3\nA=[[0.5, 0.1], [0.0, 0.4]]\nB0=[[0.2], [0.3]]\n'
        "B1=[[0.1], [0.1]]\nC=[[0.0, 0.0]]\nDf=[[0.2], [0.2]]\nDd=[[0.0], [0.2]]\nE=[[0.0], [1.0]]\n"
    )
    out = tmp_path / "g.toml"
    proc = fm("design", "--plant", str(plant), "--method", "paper", "--out", str(out))
    assert proc.returncode not in (0, 1) and not out.exists()
    assert "error:" in proc.stderr and "Traceback" not in proc.stderr


def test_bad_gains_file_is_one_line(tmp_path):
    bad = tmp_path / "g.toml"
    bad.write_text('[gains]\nL = [[1.0], [2.0]]\nM = [[1.0]]\nK1 = [[0.0]]\nK2 = [[0.0]]\nK3 = "x"\n')
    proc = fm("verify", "--plant", "paper", "--gains", str(bad))
    assert proc.returncode == 2 and "gains.K3" in proc.stderr and "Traceback" not in proc.stderr
