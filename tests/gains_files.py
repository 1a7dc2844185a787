"""A hand-made gains file, shared by the test modules that need a gains file but not a design.

Why: a vehicle table, a link, a log reader or a daemon's restart logic behaves the same whatever the gains; writing
these fixed gains costs nothing, where the certified design (the ``gains_file`` fixture of ``tests/conftest.py``)
costs seconds. The module-scoped ``gains_path`` fixture there is this file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.design.result import DesignResult
from monitor.gains import write_gains
from monitor.model.closed_loop import Gains
from monitor.model.plant import load_plant


def hand_made_gains_file(path: Path, plant_name: str = "paper-continuous") -> Path:
    """A hand-made stabilising-enough gains file (the table's logic does not depend on the design)."""
    plant = load_plant(plant_name)
    gains = Gains(
        L=np.array([[1.8], [1.6]]),
        M=np.array([[0.9]]),
        K1=np.array([[-0.26]]),
        K2=np.array([[0.1]]),
        K3=np.array([[-1.0]]),
    )
    result = DesignResult(
        method="test", gains=gains, gamma_e=1.0, gamma_z=1.0, build_seconds=0.0, solve_seconds=0.0, total_seconds=0.0
    )
    write_gains(path, result, plant)
    return path


def paper_plant_sampled_at(path: Path, h: float) -> Path:
    """The paper's continuous plant sampled at ``h`` (a log's own rate) with a delay bound inside one sample: a
    plant of the right rate for a log whose signals are what a test checks, not the plant's."""
    from importlib import resources

    preset = resources.files("monitor.presets").joinpath("paper-continuous.toml").read_text("utf-8")
    text = preset.replace("\nh = 1.0\n", f"\nh = {h!r}\n", 1).replace("tau_max = 0.4612", f"tau_max = {h / 2!r}")
    path.write_text(text)
    return path
