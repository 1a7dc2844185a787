"""Plain records that cross from the live loop to its sinks (the Rerun recorder, tests, the demo).

Why a separate module with no heavy imports: the loop builds one ``SampleRecord`` per processed sample
and hands it to the recorder without the loop importing rerun, and ``replay`` rebuilds the same records
from a file, so both ends agree on one shape. Plain lists (not numpy arrays) keep the records cheap to
copy, trivially JSON-able, and free of aliasing with the estimator's mutable state.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SampleRecord", "TruthRecord"]


@dataclass
class SampleRecord:
    """Everything the monitor knows about one processed sample of one vehicle.

    Units: angles in degrees (``alpha``, ``elevator``), rates in deg/s (``q``), times in seconds. ``alpha``,
    ``q`` and ``elevator`` are None when the vehicle's signal map has no such signal (a row not recorded).
    ``t`` is the sampling instant stamped by the vehicle (MAVLink ``time_usec``), ``wall`` the monitor's
    receive time (Unix epoch). ``y``, ``x_hat``, ``f_hat``, ``u`` and ``residual`` are in plant units.
    """

    sysid: int
    k: int
    t: float
    wall: float
    y: list[float]
    alpha: float | None
    q: float | None
    elevator: float | None
    x_hat: list[float]
    f_hat: list[float]
    u: list[float]
    residual: list[float]
    tau_obs: float | None
    processing_s: float
    alarm: bool
    run: int = 0  # 0 for a vehicle's first estimator, 1, 2, ... after each restart (runs are kept apart)
    point: int | None = None  # an envelope model: the index of the point that estimated the sample (None: one point)
    inside: bool | None = None  # ... and whether its schedule values were inside the identified range
    shed: int = 0  # the vehicle's samples shed so far under overload (not answered; lost samples to the estimator)
    served: bool | None = None  # a monitor group: did this member answer the sample (False: kept warm); None: alone


@dataclass
class TruthRecord:
    """The simulator's ground truth for one sample (contract payload ``uav/<sysid>/truth``)."""

    sysid: int
    k: int
    t: float
    x: list[float]
    f: list[float]
    d: list[float]
    tau: float | None
