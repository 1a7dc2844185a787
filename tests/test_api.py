"""The notebook API: its doctests run here, and a fresh interpreter can follow the example of its reference page
(docs/reference/api.md)."""

from __future__ import annotations

import doctest
import subprocess
import sys

import numpy as np
import pytest

import monitor.api
from tests.readme_blocks import Session, group


def test_the_api_docstrings_are_true():
    failures, attempted = doctest.testmod(monitor.api, optionflags=doctest.ELLIPSIS)
    assert attempted >= 10 and failures == 0


def test_the_readme_python_block_runs_as_it_stands_in_a_fresh_directory(tmp_path):
    """The API page's notebook example, copied as it stands, in a plain interpreter: it makes the recording it
    reads."""
    (block,) = group("notebook")  # the block marked <!-- readme: run notebook --> (tests/readme_blocks.py)
    with Session(tmp_path) as s:
        (script,) = s.run(block)  # a script in a fresh directory; it must exit 0
    *_, simulated, replayed = script.out().split()
    assert simulated == replayed and 2 <= int(simulated) <= 6  # report() on sim.rrd agrees with the simulation
    from monitor.api import read_recording

    (series,) = read_recording(s.dir / "sim.rrd").vehicles.values()
    assert len(series.samples) == 100 and len(series.truth) == 100
    assert series.truth[30].f == [2.0] and series.samples[30].k == 30


def test_importing_monitor_stays_cheap_and_unknown_names_fail_clearly():
    out = subprocess.run(
        [sys.executable, "-c", "import sys, monitor; print('scipy' in sys.modules)"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.stdout.strip() == "False"  # the daemons import monitor.* without the design stack
    with pytest.raises(AttributeError, match="no attribute 'desing'"):
        monitor.desing  # noqa: B018


def test_a_python_control_statespace_is_accepted():
    import control  # in the test extra: this test runs in CI, it never skips

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


def test_the_package_re_exports_exactly_the_api_lazily_and_for_type_checkers():
    """monitor/__init__.py names the API twice, for its lazy __getattr__ and in a TYPE_CHECKING block for editors;
    both must be monitor.api's __all__, or a name would be Any to an editor or missing at run time."""
    import ast
    from pathlib import Path

    import monitor

    tree = ast.parse(Path(monitor.__file__).read_text())
    typed = {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for imp in node.body
        if isinstance(imp, ast.ImportFrom) and imp.module == "monitor.api"
        for alias in imp.names
    }
    assert set(monitor._API) == set(monitor.api.__all__) == typed
