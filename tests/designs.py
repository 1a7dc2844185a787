"""Designs shared by the test modules, computed once per test session (the H-infinity design alone costs ~3 s).

Why a file cache next to the in-process one: under pytest-xdist each worker is a process of its own, and
both workers used to compute the same designs (paper and paper-continuous, every method), some 20 s of
the suite. The first worker to need a design computes it under a file lock and leaves it in the session's
shared temporary directory (``TESTS_DESIGN_CACHE``, set by ``tests/conftest.py``); the other reads it.
Every design is still computed for real, once per session.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import pickle
import warnings
from functools import cache
from pathlib import Path

from monitor.design import run_design
from monitor.design.result import DesignResult
from monitor.model.plant import Plant, load_plant

CACHE_ENV = "TESTS_DESIGN_CACHE"


def _compute(plant: Plant, method: str, objective: str | None, max_losses: int) -> DesignResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        options = {"objective": objective} if objective else {}
        return run_design(method, plant, max_losses=max_losses, **options)


@cache
def designed(preset: str, method: str, objective: str | None = None, max_losses: int = 0) -> tuple[Plant, DesignResult]:
    """``(plant, result)``; callers must not mutate the result (it is shared)."""
    plant = load_plant(preset)
    folder = os.environ.get(CACHE_ENV)
    if not folder:
        return plant, _compute(plant, method, objective, max_losses)
    key = hashlib.sha256(repr((plant.digest, method, objective, max_losses)).encode()).hexdigest()[:24]
    path = Path(folder) / f"design-{key}.pickle"
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the other worker waits for this design instead of computing it too
        if path.exists():
            return plant, pickle.loads(path.read_bytes())
        result = _compute(plant, method, objective, max_losses)
        path.write_bytes(pickle.dumps(result))
        return plant, result
