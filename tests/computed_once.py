"""A check that a test runs twice on the same inputs, computed once: ``computed_once(monkeypatch, module, name)``.

Why: a command's two answers (its text and its JSON, a file and the same file with one figure edited) go through
the same per-point computation on the same plant and gains, seconds each. A test that reads both answers needs the
computation once; computing it again proves nothing the first run did not. Each distinct call is still computed for
real: the key is the plant's source and digest and every other argument (pickled), so a point's single-point file
and the same point inside an envelope (different sources) are two computations, and an independent check stays
independent.
"""

from __future__ import annotations

import pickle
from types import ModuleType
from typing import Any

import pytest


def computed_once(monkeypatch: pytest.MonkeyPatch, module: ModuleType, name: str) -> dict[tuple, Any]:
    """Replace ``module.name`` (a function of a plant first) for the test by one that remembers its answers; returns
    them by key, so the test can say how many distinct calls there were."""
    real = getattr(module, name)
    seen: dict[tuple, Any] = {}

    def once(plant, *args, **kwargs):
        try:
            key = (plant.source, plant.digest, pickle.dumps((args, sorted(kwargs.items()))))
        except (pickle.PicklingError, AttributeError, TypeError):  # a callback among the arguments: not remembered
            return real(plant, *args, **kwargs)
        if key not in seen:
            seen[key] = real(plant, *args, **kwargs)
        return seen[key]

    monkeypatch.setattr(module, name, once)
    return seen
