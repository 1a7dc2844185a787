"""Test-session configuration shared by every module.

Why the end-to-end tests form one xdist group: they start daemons that pace themselves on the wall clock at a
speed-up (a sample every 40 ms at 25x), and their verdicts (commands in time, settling) hold only while the
real path stays within the plant's delay interval. Two of them at once on a 2-core machine, each with a
monitor, a vehicle and a Zenoh bus, pushed true delays past the interval in a CI run (settling 8 samples after
onset instead of 2-6). In one group they run one after another on one worker, while the other worker takes
the unit tests.

Why every other module is a group of its own: a module-scoped fixture (a margin search, a design through the CLI)
runs once per worker that gets one of the module's tests; spread over two workers it ran twice (16 s each).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.designs import CACHE_ENV

E2E = Path(__file__).parent / "e2e"
# end-to-end modules whose verdicts do not hang on the wall-clock pace of a closed loop (a vehicle alone,
# seeded draws, warnings, a log read back): they may share the CPU with another test, as unit tests do
NOT_PACED = {"test_sim_vehicle", "test_router", "test_identify_flight", "test_link_peers", "test_sim_aircraft"}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        path = Path(str(item.fspath))
        paced = E2E in path.parents and path.stem not in NOT_PACED
        group = "e2e-daemons" if paced else f"module-{path.stem}"
        item.add_marker(pytest.mark.xdist_group(group))


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
