"""Test-session configuration shared by every module.

Why the end-to-end tests form one xdist group: they start daemons that pace themselves on the wall clock at a
speed-up (a sample every 40 ms at 25x), and their verdicts (commands in time, settling) hold only while the
real path stays within the plant's delay interval. Two of them at once on a 2-core machine, each with a
monitor, a vehicle and a Zenoh bus, pushed true delays past the interval in a CI run (settling 8 samples after
onset instead of 2-6). In one group they run one after another on one worker, while the other worker takes
the unit tests.

Why every other module is a group of its own: a module-scoped fixture (a margin search, a design through the CLI)
runs once per worker that gets one of the module's tests; spread over two workers it ran twice (16 s each).

How the groups reach xdist: ``--dist loadgroup`` reads ``xdist_group`` marks by appending the group to each test's
node id, which pytest 9 no longer honours (it keeps node ids elsewhere), so with the pinned pytest 9.2 / xdist 3.8
every test was scheduled alone: e2e tests ran two at a time and the margin module's fixture ran on both workers
(45 s each). ``pytest_xdist_make_scheduler`` (xdist's hook) schedules by the same groups directly. The marks stay,
for ``pytest --markers`` and for an xdist that reads them again.
"""

from __future__ import annotations

import os

# One BLAS thread per test process (set before numpy loads; inherited by the daemons and commands the tests
# start). The matrices here are at most ~30x30, so threads only add overhead, and two xdist workers on two cores
# each running two threads oversubscribe them: the margin search took 17.9 s of CPU threaded, 9.6 s in one thread.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from pathlib import Path

import pytest

from tests.designs import CACHE_ENV

E2E = Path(__file__).resolve().parent / "e2e"
# end-to-end modules whose verdicts do not hang on the wall-clock pace of a closed loop (a vehicle alone,
# seeded draws, warnings, a log read back): they may share the CPU with another test, as unit tests do
NOT_PACED = {"test_sim_vehicle", "test_router", "test_identify_flight", "test_link_peers", "test_sim_aircraft"}


def _group(path: Path) -> str:
    path = path.resolve()
    paced = E2E in path.parents and path.stem not in NOT_PACED
    return "e2e-daemons" if paced else f"module-{path.stem}"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        item.add_marker(pytest.mark.xdist_group(_group(Path(str(item.fspath)))))


def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """With ``--dist loadgroup``: one work unit per group above, found from the node id's file."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    root = config.rootpath

    class ByGroup(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _group(root / nodeid.split("::", 1)[0])

    return ByGroup(config, log)


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
