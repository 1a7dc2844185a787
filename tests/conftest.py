"""Test-session configuration shared by every module.

Why the end-to-end tests form one xdist group: they start daemons that pace themselves on the wall clock at a
speed-up (a sample every 40 ms at 25x), and their verdicts (commands in time, settling) hold only while the
real path stays within the plant's delay interval. Two of them at once on a 2-core machine, each with a
monitor, a vehicle and a Zenoh bus, pushed true delays past the interval in a CI run (settling 8 samples after
onset instead of 2-6). In one group they run one after another on one worker, while the other worker takes
the unit tests.

Why every other module is a group of its own: a module-scoped fixture (a margin search, a design through the CLI)
runs once per worker that gets one of the module's tests; spread over two workers it ran twice (16 s each).

How the groups reach xdist: ``--dist loadgroup`` reads the ``xdist_group`` marks added below. The hook runs
first (``tryfirst``) so that the marks are there when xdist's own collection hook reads them. pytest 9.2 changed
how node ids are kept and xdist 3.8's loadgroup then silently ignores every group (pytest-dev/pytest-xdist#1386,
open): the test extra and constraints.txt hold pytest below 9.2 until xdist follows.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# One BLAS thread per test process (set before numpy loads; inherited by the daemons and commands the tests
# start). The matrices here are at most ~30x30, so threads only add overhead, and two xdist workers on two cores
# each running two threads oversubscribe them: the margin search took 17.9 s of CPU threaded, 9.6 s in one thread.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from tests.designs import CACHE_ENV  # noqa: E402 - it imports numpy, which must come after the setting above

E2E = Path(__file__).resolve().parent / "e2e"
# end-to-end modules whose verdicts do not hang on the wall-clock pace of a closed loop (a vehicle alone,
# seeded draws, warnings, a log read back): they may share the CPU with another test, as unit tests do
NOT_PACED = {
    "test_sim_vehicle",
    "test_router",
    "test_identify_flight",
    "test_link_peers",
    "test_sim_aircraft",
    "test_envelope_manoeuvres",  # a mission flown as fast as JSBSim goes, read back from its log
    "test_design_cluster",  # a design on a Dask scheduler and worker: no loop, no pace
}


def _group(path: Path, not_paced: bool = False) -> str:
    """``not_paced``: a test of a paced module that is not paced itself (``@pytest.mark.not_paced``: a refusal, a log
    read back, a flight as fast as JSBSim goes) runs beside the unit tests, in its module's own group, and leaves
    the serial group's time to the paced loops."""
    path = path.resolve()
    paced = E2E in path.parents and path.stem not in NOT_PACED and not not_paced
    return "e2e-daemons" if paced else f"module-{path.stem}"


# modules outside tests/e2e that start daemons (fault-monitor run, sim-vehicle, a Zenoh router, MAVProxy)
DAEMON_MODULES = {"test_readme", "test_recording_runs", "test_recorder", "test_live_sinks"}
# modules whose tests take seconds each (designs through the CLI, margin searches, daemons); the rest of the
# suite, `pytest -m "not slow"`, runs in well under a minute on two workers
SLOW_MODULES = DAEMON_MODULES | {
    "test_threshold",
    "test_design",
    "test_design_portability",
    "test_losses",
    "test_margin",
    "test_cli_offline",
    "test_api",
    "test_analyse",
    "test_detectability_jsbsim",
    "test_multi_delay",
    "test_verify_output",
}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "daemons: starts daemons or programs on loopback (tests/e2e and DAEMON_MODULES)")
    config.addinivalue_line("markers", "slow: seconds per test; `-m 'not slow'` is the quick subset")
    config.addinivalue_line(
        "markers", "not_paced: an end-to-end test no paced loop's verdict hangs on: out of the serial xdist group"
    )


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        path = Path(str(item.fspath)).resolve()
        item.add_marker(pytest.mark.xdist_group(_group(path, item.get_closest_marker("not_paced") is not None)))
        in_e2e = E2E in path.parents
        if in_e2e or path.stem in DAEMON_MODULES:
            item.add_marker(pytest.mark.daemons)
        if in_e2e or path.stem in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)


def pytest_runtest_setup(item: pytest.Item) -> None:
    """The serial group's first test starts, at a low priority, the commands its later tests need the output of
    (``tests/ahead.py``: the long-delay design)."""
    group = item.get_closest_marker("xdist_group")
    if group is not None and group.args[0] == "e2e-daemons":
        from tests.ahead import start_for_session

        start_for_session(item.session.items)


def pytest_sessionfinish(session: pytest.Session) -> None:
    from tests.ahead import stop_all

    stop_all()


@pytest.fixture(scope="session", autouse=True)
def shared_design_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """One design cache for the session, shared by the xdist workers (``tests/designs.py``)."""
    if os.environ.get(CACHE_ENV):
        return
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # pytest-N/, above popen-gwK/
    folder = shared / "designs"
    folder.mkdir(exist_ok=True)
    os.environ[CACHE_ENV] = str(folder)


# -- gains files shared by many modules (fixtures live here, never imported from a test module) -----------------


@pytest.fixture(scope="session")
def gains_file(tmp_path_factory) -> Path:
    """The default certified design for paper-continuous (what `fault-monitor design` writes), once per session
    (the design itself once for both workers: ``tests/designs.py``)."""
    from monitor.gains import write_gains
    from tests.designs import designed

    plant, result = designed("paper-continuous", "certified")
    path = tmp_path_factory.mktemp("gains") / "certified.toml"
    write_gains(path, result, plant)
    return path


@pytest.fixture(scope="module")
def gains_path(tmp_path_factory) -> Path:
    """Hand-made gains for paper-continuous, once per module (``tests/gains_files.py``: no design, for tests whose
    logic does not depend on the design); not the certified ``gains_file``."""
    from tests.gains_files import hand_made_gains_file

    return hand_made_gains_file(tmp_path_factory.mktemp("g") / "gains.toml")
