"""UAV telemetry-in-the-loop fault monitor.

The maths core (``plant``, ``discretize``, ``closed_loop``, ``design``, ``verify``) is pure: no sockets,
files or clocks, so the offline tools, the live service and the tests all run the same functions.

The public surface for notebooks and scripts is re-exported here (``monitor.api``): load or build a
plant, design, verify, simulate, read a recording. Everything else may move between versions.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

_API = ("Gains", "Plant", "DesignResult", "Verdict", "SimulatedRun", "load_plant", "plant_from_arrays",
        "plant_from_statespace", "design_gains", "check_gains", "check_losses", "simulate", "read_gains",
        "read_recording", "report")

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    """Import the API lazily: the daemons import ``monitor.*`` submodules and must not pay for numpy/scipy here."""
    if name in _API:
        from monitor import api

        return getattr(api, name)
    raise AttributeError(f"module 'monitor' has no attribute {name!r}")
