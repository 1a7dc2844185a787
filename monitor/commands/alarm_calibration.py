"""``--alarm-threshold auto --turbulence LEVEL --calibration-log LOG``: the threshold checked against flights.

Why: the threshold ``auto`` sets in turbulence is Rice's formula on the Gaussian f_hat of the linear loop
(``monitor.checks.detectability``). Real estimates have heavier tails (the plant is not linear, the gusts are not
the model's Gauss-Markov process): on JSBSim's t6texan2, 30 minutes of level flight in light turbulence crossed the
Gaussian once-per-hour level 24 times. Fault-free logs of the vehicle in that air are read by the same estimator
as ``analyse`` (the fleet's own plant and gains, every sample), and ``monitor.checks.calibration`` fits the tail of
their crossing rates and puts the budget where the fit says; the threshold kept is the larger of the two. The logs
must be flown in the turbulence given (f_hat scales with it), fault-free, and long enough to cross the upper
levels several times (tens of minutes); too short a log is said in one line and the Gaussian threshold is kept.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from monitor.checks.calibration import Calibration, calibrate_threshold
from monitor.errors import UserError
from monitor.service.alarm import AlarmConfig

__all__ = ["calibrate_on_logs"]

log = logging.getLogger("monitor.alarm")
_NEVER = AlarmConfig(1e300, 5e299, 1)  # the logs are read for f_hat alone: no alarm is wanted from them


def _series(path: str, fleet) -> tuple[list[np.ndarray], float]:
    """Every fault channel's f_hat of every vehicle in the log, as analyse computes it, and the sample period."""
    from monitor.link.onboard_log import open_onboard_log
    from monitor.service.offline import analyse_dataflash, analyse_log

    if not Path(path).is_file():
        raise UserError(f"--calibration-log {path}: no such log file")
    dlog = open_onboard_log(path)
    try:
        result = analyse_dataflash(dlog, fleet, _NEVER) if dlog is not None else analyse_log(path, fleet, _NEVER)
    finally:
        if dlog is not None:
            dlog.close()
    by_vehicle: dict[int, list] = {}
    for record in result.records:
        by_vehicle.setdefault(record.sysid, []).append(record.f_hat)
    if not by_vehicle:
        raise UserError(f"--calibration-log {path}: no sample of the fleet's signals could be assembled from it")
    series = [np.asarray(rows, dtype=float)[:, j] for rows in by_vehicle.values() for j in range(len(rows[0]))]
    return series, fleet.default.plant.h


def calibrate_on_logs(logs: Sequence[str], fleet, gaussian: float, per_hour: float) -> tuple[float, Calibration | None]:
    """``(threshold, calibration)``: the calibrated threshold (never below ``gaussian``), or ``gaussian`` and None
    when the logs cross too few levels often enough to fit (said in one WARNING line)."""
    series: list[np.ndarray] = []
    h = 0.0
    for path in logs:
        found, h = _series(path, fleet)
        series += found
    calibration = calibrate_threshold(series, h, per_hour, gaussian)
    minutes = sum(len(s) for s in series) * h / 60.0
    if calibration is None:
        log.warning(
            "alarm threshold auto: %.1f min of --calibration-log cross too few levels often enough to fit their "
            "tail; the Gaussian threshold %.4g is kept (fly longer: tens of minutes)",
            minutes,
            gaussian,
        )
        return gaussian, None
    fit = ", ".join(f"{f.shape} {f.per_hour(calibration.threshold):.2g}/h" for f in calibration.fits)
    log.info(
        "alarm threshold auto: calibrated on %.1f min of flight: %.4g (kept: %s; the Gaussian %.4g is crossed "
        "about %.2g times per hour there by the flights' fit); at the calibrated level the fits give %s",
        minutes,
        calibration.threshold,
        calibration.kept,
        gaussian,
        calibration.prediction_per_hour_by_flights,
        fit,
    )
    return calibration.threshold, calibration
