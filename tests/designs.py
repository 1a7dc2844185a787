"""Designs shared by the test modules, computed once per session (the H-infinity design alone costs ~3 s)."""

from __future__ import annotations

import warnings
from functools import lru_cache

from monitor.design import run_design
from monitor.design.result import DesignResult
from monitor.model.plant import Plant, load_plant


@lru_cache(maxsize=None)
def designed(preset: str, method: str, objective: str | None = None, max_losses: int = 0) -> tuple[Plant, DesignResult]:
    """``(plant, result)``; callers must not mutate the result (it is shared)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plant = load_plant(preset)
        options = {"objective": objective} if objective else {}
        return plant, run_design(method, plant, max_losses=max_losses, **options)
