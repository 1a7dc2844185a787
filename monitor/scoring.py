"""Score a recorded run offline: detection and false alarms, settling of f_hat, errors against the true fault.

The engine of ``fault-monitor replay`` (and of ``analyse``'s report): it scores the rows that
``monitor.service.recording_reader`` rebuilds from a recording (or that ``analyse`` assembles from a log).

Where the fault comes from, in order: the truth stream recorded beside the estimates (``truth/f``),
else a fault SPEC given by the caller (``--fault bias:2@20``), else nothing (then settling and the
estimation error are ``None``). The scores are those of ``monitor.checks.metrics`` on the fault's first
component (the elevator fault).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.checks import metrics
from monitor.errors import UserError
from monitor.service.recording_reader import Recording, VehicleSeries
from monitor.service.records import TruthRecord

__all__ = ["score_recording", "score_vehicle", "SETTLING_TOL"]

SETTLING_TOL = 0.05


@dataclass(frozen=True)
class _Fault:
    """The true fault on the recorded samples: f(k) per sample, onset, size, episode end, source."""

    f: np.ndarray
    onset: int | None
    size: float | None
    stop: int | None
    source: str
    spec: str | None = None


def _fault_from_truth(k: np.ndarray, truth: list[TruthRecord]) -> _Fault | None:
    by_k = {r.k: (r.f[0] if r.f else math.nan) for r in truth}
    if not by_k or all(math.isnan(v) for v in by_k.values()):
        return None
    f = np.array([by_k.get(int(kk), math.nan) for kk in k])
    tk = np.array(sorted(by_k))
    tf = np.array([by_k[kk] for kk in tk])
    faulty = np.flatnonzero(np.abs(tf) > 0)
    if not faulty.size:
        return _Fault(f, None, None, None, "truth")
    onset = int(tk[faulty[0]])
    healed = np.flatnonzero((tk > onset) & (tf == 0))
    stop = int(tk[healed[0]]) if healed.size else None
    window = (tk >= onset) & (tk < stop if stop is not None else True)
    return _Fault(f, onset, float(np.max(np.abs(tf[window]))), stop, "truth")


def _fault_from_spec(k: np.ndarray, spec: str) -> _Fault:
    from monitor.wire.specs import parse_fault_spec  # lazy: the grammar lives with the simulator's parser

    schedule = parse_fault_spec(spec)
    f = np.array([schedule.f(int(kk)) for kk in k], dtype=float)
    onset = schedule.onset
    if onset is None:
        return _Fault(f, None, None, None, "spec", spec)
    ends = [ev.end for ev in schedule.events if ev.start == onset]
    bounded = [end for end in ends if end is not None]
    stop = max(bounded) if len(bounded) == len(ends) else None  # an intermittent fault is scored on its episode
    window = (k >= onset) & (k < stop if stop is not None else True)
    size = float(np.max(np.abs(f[window]))) if window.any() else None
    return _Fault(f, onset, size, stop, "spec", spec)


def _step_seconds(k: np.ndarray, t: np.ndarray) -> float | None:
    """The sampling period seen in the recording (median t step per k step), to turn steps into seconds."""
    if k.size < 2:
        return None
    dk, dt = np.diff(k), np.diff(t)
    ok = (dk > 0) & np.isfinite(dt)
    return float(np.median(dt[ok] / dk[ok])) if ok.any() else None


def _times(value: int | None, h: float | None) -> float | None:
    return None if value is None or h is None else value * h


def score_vehicle(series: VehicleSeries, fault_spec: str | None = None, tol: float = SETTLING_TOL) -> dict[str, Any]:
    """Every score of one vehicle, as a JSON-able dict (see ``fault-monitor replay --help`` for the keys).

    A vehicle that restarted has several runs (k starts again): ``samples`` counts every processed sample
    of every run, ``runs`` how many there were, and the scores are those of the last run.
    """
    runs = sorted({r.run for r in series.samples})
    total = len(series.samples)
    s = [r for r in series.samples if r.run == runs[-1]] if len(runs) > 1 else series.samples
    k = np.array([r.k for r in s], dtype=np.int64)
    t = np.array([r.t for r in s], dtype=float)
    f_hat = np.array([r.f_hat[0] if r.f_hat else math.nan for r in s], dtype=float)
    alarm = np.array([r.alarm for r in s], dtype=bool)
    alpha = np.array([r.alpha for r in s], dtype=float)
    h = _step_seconds(k, t)

    # an explicit --fault SPEC is what the user asked to be scored against; the recorded truth otherwise
    truth_fault = _fault_from_truth(k, series.truth) if series.truth else None
    fault = _fault_from_spec(k, fault_spec) if fault_spec is not None else truth_fault
    note = None
    if fault_spec is not None and truth_fault is not None:
        note = f"scored against --fault {fault_spec}; the recording also holds the simulator's truth"
    onset = fault.onset if fault else None
    known = ~np.isnan(fault.f) if fault else np.zeros(k.size, bool)

    first_any = metrics.first_alarm(k, alarm)
    detected = metrics.first_alarm(k, alarm, start=onset) if onset is not None else None
    settling = None
    if fault and onset is not None and fault.size:
        settling = metrics.settling_steps(k[known], f_hat[known], fault.f[known], onset, fault.size, tol, fault.stop)
    rms_ef = rms_ef_post = None
    if fault and known.any():
        rms_ef = metrics.rms_error(k[known], f_hat[known], fault.f[known])
        if onset is not None:
            rms_ef_post = metrics.rms_error(k[known], f_hat[known], fault.f[known], start=onset)
    t_of = dict(zip(k.tolist(), t.tolist(), strict=True))
    processing = [r.processing_s * 1e3 for r in s]
    return {
        "sysid": series.sysid,
        "samples": total,
        "runs": max(1, len(runs)),
        "last_run_samples": int(k.size),
        "k_first": int(k[0]) if k.size else None,
        "k_last": int(k[-1]) if k.size else None,
        "missing": int(k[-1] - k[0] + 1 - k.size) if k.size else 0,
        "t_first": float(t[0]) if k.size else None,
        "t_last": float(t[-1]) if k.size else None,
        "h": h,
        "fault_source": fault.source if fault else None,
        "fault_spec": fault.spec if fault else None,
        "onset_k": onset,
        "fault_size": fault.size if fault else None,
        "first_alarm_k": first_any,
        "first_alarm_t": t_of.get(first_any) if first_any is not None else None,
        "detection_k": detected,
        "detection_steps": None if detected is None or onset is None else detected - onset,
        "detection_s": _times(None if detected is None or onset is None else detected - onset, h),
        # with no known fault (no truth, no SPEC) a raise cannot be called false: None, not a guess
        "false_alarms": metrics.false_alarms(k, alarm, onset) if fault is not None else None,
        "fault_note": note,
        "alarm_samples": int(alarm.sum()),
        "settling_tol": tol,
        "settling_steps": settling,
        "settling_s": _times(settling, h),
        "rms_ef": rms_ef,
        "rms_ef_after_onset": rms_ef_post,
        "peak_alpha": metrics.peak_abs(alpha),
        "rms_alpha": metrics.rms(alpha[~np.isnan(alpha)]),
        "peak_q": metrics.peak_abs(np.array([r.q for r in s], dtype=float)),
        "tau_obs_s": metrics.percentiles([r.tau_obs for r in s if r.tau_obs is not None]),
        "tau_true_s": metrics.percentiles([r.tau for r in series.truth if r.tau is not None]),
        "processing_ms": metrics.percentiles(processing),
        "truth_samples": len(series.truth),
    }


def _worst(values: list[Any]) -> Any:
    """Fleet summary of a lower-is-better score: None if any vehicle has None (never happened), else max."""
    return None if not values or any(v is None for v in values) else max(values)


def score_recording(
    recording: Recording, sysid: int | None = None, fault_spec: str | None = None, tol: float = SETTLING_TOL
) -> dict[str, Any]:
    """The report of ``fault-monitor replay --json``.

    Shape: ``{"file", "application_id", "complete", "properties", "sysids", "vehicles": {"<sysid>": {..}},
    ...}``. With exactly one vehicle (or ``sysid`` given) its scores are also at the top level; with
    several, the top level holds the fleet summary under the same keys: ``samples`` summed,
    ``false_alarms`` summed, ``peak_alpha`` and ``rms_ef`` the largest, ``settling_steps`` and
    ``detection_steps`` the worst over the faulty vehicles (``null`` when any of them never settled or
    was never detected, or when no vehicle has a known fault).
    """
    vehicles = recording.vehicles
    if sysid is not None:
        if sysid not in vehicles:
            have = ", ".join(map(str, vehicles)) or "none"
            raise UserError(f"{recording.path}: no vehicle {sysid} in the recording (vehicles: {have})")
        vehicles = {sysid: vehicles[sysid]}
    per = {s: score_vehicle(v, fault_spec, tol) for s, v in vehicles.items()}
    out: dict[str, Any] = {
        "file": str(recording.path),
        "application_id": recording.application_id,
        "complete": recording.has_footer,
        "properties": recording.properties,
        "sysids": list(per),
    }
    if len(per) == 1:
        out.update(next(iter(per.values())))
    else:
        rows = list(per.values())
        faulty = [r for r in rows if r["onset_k"] is not None]
        out.update(
            {
                "samples": sum(r["samples"] for r in rows),
                "false_alarms": (
                    None if any(r["false_alarms"] is None for r in rows) else sum(r["false_alarms"] for r in rows)
                ),
                "peak_alpha": max((r["peak_alpha"] for r in rows if r["peak_alpha"] is not None), default=None),
                "rms_ef": max((r["rms_ef"] for r in rows if r["rms_ef"] is not None), default=None),
                "settling_steps": _worst([r["settling_steps"] for r in faulty]),
                "detection_steps": _worst([r["detection_steps"] for r in faulty]),
            }
        )
    out["vehicles"] = {str(s): r for s, r in per.items()}
    return out
