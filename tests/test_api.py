"""The notebook API: its doctests run here, and a fresh interpreter can follow the README's example."""

from __future__ import annotations

import doctest
import subprocess
import sys

import numpy as np
import pytest

import monitor.api


def test_the_api_docstrings_are_true():
    failures, attempted = doctest.testmod(monitor.api, optionflags=doctest.ELLIPSIS)
    assert attempted >= 10 and failures == 0


def test_a_plain_python_session_can_follow_the_readme():
    script = """
import numpy as np
from monitor import plant_from_arrays, design_gains, check_gains, check_losses, simulate
plant = plant_from_arrays(h=1.0, tau_max=0.3, A_c=[[-1.0, 1.0], [0.0, -3.0]], B_c=[[0.0], [2.0]],
                          D_cf=[[0.0], [1.0]], D_cd=[[0.5], [1.0]], C=[[1.0, 0.0]])
result = design_gains(plant, max_losses=1)
v = check_gains(plant, result.gains, result)
losses = check_losses(plant, result.gains, 1, result)
run = simulate(plant, result.gains, steps=60, fault="bias:1@10", seed=3)
print(v.stable, v.certificate_valid, losses.stable, run.settling_steps, bool(np.all(np.isfinite(run.f_hat))))
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    stable, cert, losses, settling, finite = out.stdout.split()
    assert (stable, cert, losses, finite) == ("True", "True", "True", "True")
    assert int(settling) <= 6


def test_importing_monitor_stays_cheap_and_unknown_names_fail_clearly():
    out = subprocess.run([sys.executable, "-c", "import sys, monitor; print('scipy' in sys.modules)"],
                         capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "False"  # the daemons import monitor.* without the design stack
    with pytest.raises(AttributeError, match="no attribute 'desing'"):
        monitor.desing  # noqa: B018


def test_a_python_control_statespace_is_accepted_when_installed():
    control = pytest.importorskip("control")
    sys_ = control.ss([[-1.0, 1.0], [0.0, -3.0]], [[0.0, 0.0, 0.5], [2.0, 1.0, 1.0]], [[1.0, 0.0]], [[0.0, 0.0, 0.0]])
    plant = monitor.api.plant_from_statespace(sys_, h=1.0, tau_max=0.3)
    assert np.allclose(plant.continuous.D_cd, [[0.5], [1.0]])


def test_bad_statespace_inputs_are_one_line_errors():
    from monitor.errors import UserError

    class Discrete:
        A, B, C, D, dt = [[0.5]], [[1.0, 1.0, 1.0]], [[1.0]], [[0.0, 0.0, 0.0]], 1.0

    with pytest.raises(UserError, match="continuous-time"):
        monitor.api.plant_from_statespace(Discrete(), h=1.0, tau_max=0.3)
    Discrete.dt = 0
    with pytest.raises(UserError, match="fault columns"):
        monitor.api.plant_from_statespace(Discrete(), h=1.0, tau_max=0.3, fault=(5,))
