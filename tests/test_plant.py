"""Plant presets and the strict plant-file validation."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.model.discretize import discretize
from monitor.model.plant import load_plant, parse_plant

PAPER_A = np.array([[0.2759, 0.1839], [0.1379, 0.0921]])
PAPER_BSUM = np.array([[0.2256 + 0.1359], [0.4234 + 0.6671]])


def test_paper_preset_is_the_printed_example():
    p = load_plant("paper")
    assert p.form == "discrete" and (p.n, p.m, p.l, p.q, p.p) == (2, 1, 1, 1, 1)
    np.testing.assert_array_equal(p.A, PAPER_A)
    assert p.delta == pytest.approx(0.3202) and p.tau_max == pytest.approx(0.4612)


def test_continuous_preset_discretised_at_zero_delay_gives_back_the_paper():
    p = load_plant("paper-continuous")
    d = discretize(p.continuous, p.h, 0.0)
    np.testing.assert_allclose(d.A, PAPER_A, atol=1e-12)
    np.testing.assert_allclose(d.B0 + d.B1, PAPER_BSUM, atol=1e-12)
    np.testing.assert_allclose(d.B1, 0.0, atol=1e-15)
    np.testing.assert_allclose(d.Df, [[0.2123], [0.2169]], atol=1e-12)
    # ...but its own split at the nominal delay is not the printed B0 (two presets, on purpose)
    assert np.linalg.norm(p.B0 - [[0.2256], [0.4234]]) > 0.1


def test_digest_depends_on_content_not_formatting():
    text = load_plant("paper").source
    assert text == "preset:paper"
    a = parse_plant(
        'form="discrete"\nh=1.0\ntau_min=0.0\ntau_max=0.4\nA=[[0.5]]\nB0=[[1.0]]\nB1=[[0.1]]\nC=[[1.0]]\nDf=[[1.0]]\nDd=[[1.0]]\n'
    )
    b = parse_plant(
        'form = "discrete"\nh = 1.0\ntau_min = 0.0\ntau_max = 0.4\nA = [[ 0.5 ]]\n'
        "B0 = [[1.0]]\nB1 = [[0.1]]\nC = [[1.0]]\nDf = [[1.0]]\nDd = [[1.0]]\n"
    )
    c = parse_plant(
        'form="discrete"\nh=1.0\ntau_min=0.0\ntau_max=0.4\nA=[[0.6]]\nB0=[[1.0]]\nB1=[[0.1]]\nC=[[1.0]]\nDf=[[1.0]]\nDd=[[1.0]]\n'
    )
    assert a.digest == b.digest != c.digest


GOOD = """form = "continuous"
h = 1.0
tau_min = 0.0
tau_max = 0.4
A_c = [[-1.0, 1.0], [0.0, -2.0]]
B_c = [[0.0], [1.0]]
D_cf = [[0.0], [1.0]]
D_cd = [[0.0], [1.0]]
C = [[1.0, 0.0]]
"""


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda t: t + "tau_mx = 0.3\n", "tau_mx"),
        (lambda t: t.replace("B_c = [[0.0], [1.0]]", "B_c = [[0.0], [1.0], [2.0]]"), "B_c"),
        (lambda t: t.replace("A_c = [[-1.0, 1.0], [0.0, -2.0]]", "A_c = [[-1.0, nan], [0.0, -2.0]]"), "A_c"),
        (lambda t: t.replace("tau_max = 0.4", "tau_max = 3.5"), "tau_max"),  # 4 whole samples: too many parts
        (lambda t: t.replace("tau_min = 0.0", "tau_min = 0.5"), "tau_min"),  # above tau_max
        (lambda t: t.replace("tau_min = 0.0", "tau_min = -0.1"), "tau_min"),
        (lambda t: t.replace("h = 1.0\n", ""), "h"),
        (lambda t: t.replace("C = [[1.0, 0.0]]", "C = [[1.0, 0.0], [1.0]]"), "C"),
        (lambda t: t.replace("D_cd = [[0.0], [1.0]]", 'D_cd = "x"'), "D_cd"),
        (lambda t: t.replace('"continuous"', '"hybrid"'), "form"),
        (lambda t: t + "[actuator]\nlimt = 3\n", "actuator.limt"),
        (
            lambda t: t + '[disturbance]\nsigma = 0.3\ntime_constant = 0.2\nturbulence = "lite"\n',
            "disturbance.turbulence",
        ),
    ],
)
def test_malformed_plant_files_name_the_key_and_the_file(tmp_path, edit, key):
    path = tmp_path / "bad.toml"
    path.write_text(edit(GOOD))
    with pytest.raises(UserError) as err:
        load_plant(path)
    msg = str(err.value)
    assert f"'{key}'" in msg and str(path) in msg and "\n" not in msg


def test_good_file_loads(tmp_path):
    path = tmp_path / "good.toml"
    path.write_text(GOOD)
    assert load_plant(path).n == 2


def test_cli_reports_a_bad_plant_in_one_line_with_exit_2(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(GOOD + "bogus = 1\n")
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "verify", "--plant", str(path), "--L", "1,1", "--M", "1", "--K1", "0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "'bogus'" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run(
        [sys.executable, "-m", "monitor", "verify", "--plant", "no-such-preset", "--L", "1,1", "--M", "1", "--K1", "0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "neither a preset" in proc.stderr
