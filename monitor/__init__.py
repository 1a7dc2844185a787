"""UAV telemetry-in-the-loop fault monitor.

The maths core (``plant``, ``discretize``, ``closed_loop``, ``design``, ``verify``) is pure: no sockets,
files or clocks, so the offline tools, the live service and the tests all run the same functions.

The public surface for notebooks and scripts is re-exported here (``monitor.api``): load or build a
plant, design, verify, simulate, read a recording. Everything else may move between versions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # what an editor and mypy see; at run time ``__getattr__`` below imports them on first use
    from monitor.api import DesignResult as DesignResult
    from monitor.api import Gains as Gains
    from monitor.api import Plant as Plant
    from monitor.api import SimulatedRun as SimulatedRun
    from monitor.api import Verdict as Verdict
    from monitor.api import check_gains as check_gains
    from monitor.api import check_losses as check_losses
    from monitor.api import design_gains as design_gains
    from monitor.api import load_plant as load_plant
    from monitor.api import plant_from_arrays as plant_from_arrays
    from monitor.api import plant_from_statespace as plant_from_statespace
    from monitor.api import read_gains as read_gains
    from monitor.api import read_recording as read_recording
    from monitor.api import report as report
    from monitor.api import simulate as simulate

__version__ = "0.1.0"

_API = (
    "Gains",
    "Plant",
    "DesignResult",
    "Verdict",
    "SimulatedRun",
    "load_plant",
    "plant_from_arrays",
    "plant_from_statespace",
    "design_gains",
    "check_gains",
    "check_losses",
    "simulate",
    "read_gains",
    "read_recording",
    "report",
)

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    """Import the API lazily: the daemons import ``monitor.*`` submodules and must not pay for numpy/scipy here."""
    if name in _API:
        from monitor import api

        return getattr(api, name)
    raise AttributeError(f"module 'monitor' has no attribute {name!r}")
