"""The demo's comparison: one row per design, every figure computed from that design's recording."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.checks import metrics
from monitor.demo.montecarlo import Trace

__all__ = ["Row", "trace_from_recording", "row_from_recording", "late_window", "format_table", "SETTLING_FLOOR"]

SETTLING_FLOOR = 2  # a floor: f(20) first reaches y(21), so no observer of form (5) settles before onset + 2


@dataclass
class Row:
    """One design's line of the comparison; a design that could not be designed has only ``failure``.

    Why the measurements may be None rather than made up: a failed design has no run, and summary.json
    must not show a verdict (``stable: false``) or figures nobody measured.
    """

    method: str
    stable: bool | None
    certificate: str | None
    gamma_e: float | None
    gamma_z: float | None
    samples: int | None
    settling_steps: int | None
    rms_ef: float | None
    peak_alpha_after: float | None
    rms_alpha_after: float | None
    alarm_delay: int | None
    false_alarms: int | None
    tau_true_p50: float | None = None
    failure: str | None = None  # why this design has no run ("design failed: ..."); None when it ran
    model: str | None = None  # the aircraft demo: which identified model the design was made for
    ef_late: float | None = None  # the aircraft demo: mean |e_f| over the second ending LATE_S after onset
    alpha_late: float | None = None  # ... and the mean alpha deviation from trim over that second (the alpha hold)

    @classmethod
    def failed(cls, method: str, failure: str, model: str | None = None) -> Row:
        """The row of a design that never ran: its name and why, every measurement None."""
        return cls(
            method, None, None, None, None, None, None, None, None, None, None, None, failure=failure, model=model
        )


def trace_from_recording(rrd: Path, fault_spec: str) -> tuple[Trace, dict]:
    """The series the figures need, read back from the recording, plus ``replay``'s analysis of it."""
    from monitor.scoring import score_recording
    from monitor.service.recording_reader import load_recording
    from monitor.wire.specs import parse_fault_spec

    recording = load_recording(rrd)
    report = score_recording(recording, fault_spec=fault_spec)
    series = next(iter(recording.vehicles.values()))
    s = series.samples
    k = np.array([r.k for r in s], dtype=int)
    truth_f = {r.k: r.f[0] for r in series.truth if r.f}
    fault = parse_fault_spec(fault_spec)
    f = np.array([truth_f.get(int(kk), fault.f(int(kk))) for kk in k])
    tau_by_k = {r.k: r.tau for r in series.truth}
    trace = Trace(
        k=k,
        f=f,
        f_hat=np.array([r.f_hat[0] for r in s]),
        alpha=np.array([r.alpha for r in s], dtype=float),
        q=np.array([r.q for r in s], dtype=float),
        u=np.array([r.u[0] for r in s]),
        tau=np.array([tau_by_k.get(int(kk)) if tau_by_k.get(int(kk)) is not None else math.nan for kk in k]),
        alarm=np.array([r.alarm for r in s], dtype=bool),
    )
    return trace, report


def row_from_recording(
    method: str,
    rrd: Path,
    fault_spec: str,
    stable: bool,
    certificate: str,
    gamma_e: float,
    gamma_z: float,
    trim: tuple[float, float] = (0.0, 0.0),
) -> tuple[Row, Trace]:
    """One design's row and trace from its recording; ``trim`` (alpha0, q0) is subtracted from the measured
    alpha and q, which the recording keeps as measured (absolute), so that an aircraft's row reads deviations."""
    trace, report = trace_from_recording(rrd, fault_spec)
    trace.alpha = trace.alpha - trim[0]
    trace.q = trace.q - trim[1]
    onset = report.get("onset_k")
    after = trace.k >= onset if onset is not None else np.zeros(trace.k.size, bool)
    tau = report.get("tau_true_s") or {}
    return Row(
        method=method,
        stable=stable,
        certificate=certificate,
        gamma_e=gamma_e,
        gamma_z=gamma_z,
        samples=report["samples"],
        settling_steps=report.get("settling_steps"),
        rms_ef=report.get("rms_ef_after_onset"),
        peak_alpha_after=metrics.peak_abs(trace.alpha[after]),
        rms_alpha_after=metrics.rms(trace.alpha[after]),
        alarm_delay=report.get("detection_steps"),
        false_alarms=report.get("false_alarms", 0),
        tau_true_p50=tau.get("p50") if isinstance(tau, dict) else None,
    ), trace


def late_window(
    trace: Trace, onset: int | None, rate: float, late_s: float = 30.0
) -> tuple[float | None, float | None]:
    """``(mean |e_f|, mean alpha)`` over the second that ends ``late_s`` after onset; None when the run is shorter.

    Why a late window and not the RMS after onset: a model that leaves out the phugoid estimates the fault
    well at first and loses it as the aircraft drifts off trim; the drift shows tens of seconds later.
    """
    if onset is None:
        return None, None
    end = onset + round(late_s * rate)
    window = (trace.k > end - round(rate)) & (trace.k <= end)
    if not window.any() or trace.k.max() < end:
        return None, None
    ef = np.abs(trace.f_hat[window] - trace.f[window])
    return float(np.mean(ef)), float(np.mean(trace.alpha[window]))


def _fmt(value, spec: str = ".3f", none: str = "never") -> str:
    if value is None:
        return none
    if isinstance(value, float) and not math.isfinite(value):
        return "inf"
    return format(value, spec)


def _cells(r: Row, aircraft: bool) -> list[str]:
    """A row's cells; a failed design has its name (and model) and why, the reason running on over the empty columns."""
    first = [r.model or "", r.method] if aircraft else [r.method]
    if r.failure is not None:
        return [*first, r.failure]
    late = [_fmt(r.ef_late, ".3g", "-"), _fmt(r.alpha_late, ".3g", "-")] if aircraft else []
    return [
        *first,
        "stable" if r.stable else "UNSTABLE",
        r.certificate or "none",
        _fmt(r.gamma_e),
        _fmt(r.gamma_z),
        str(r.samples),
        _fmt(r.settling_steps, "d"),
        _fmt(r.rms_ef, ".3g"),
        *late,
        _fmt(r.peak_alpha_after, ".3g"),
        _fmt(r.rms_alpha_after, ".3g"),
        _fmt(r.alarm_delay, "d"),
        str(r.false_alarms),
    ]


def format_table(rows: list[Row], late_s: float = 30.0) -> str:
    """The comparison; rows with a ``model`` (the aircraft demo) add it and the late-window columns."""
    aircraft = any(r.model for r in rows)
    late = [f"|e_f| {late_s:g} s after, deg", f"alpha {late_s:g} s after, deg"] if aircraft else []
    head = [
        *(["model"] if aircraft else []),
        "design",
        "real loop",
        "certificate",
        "gamma_e",
        "gamma_z",
        "samples",
        f"FE settling, samples (floor {SETTLING_FLOOR})",
        "RMS e_f after onset",
        *late,
        "peak |alpha| after, deg",
        "RMS alpha after, deg",
        "alarm delay, samples",
        "false alarms",
    ]
    body = [_cells(r, aircraft) for r in rows]
    # a failed row's reason spans the measurement columns, so it widens none of them (only its name counts)
    named = 2 if aircraft else 1
    widths = [max([len(h), *(len(b[i]) for b in body if len(b) == len(head) or i < named)]) for i, h in enumerate(head)]

    def line(cells: list[str]) -> str:
        # strict=False: a failed row has fewer cells than columns (its reason is its last cell)
        return "  ".join(c.ljust(w) for c, w in zip(cells, widths, strict=False)).rstrip()

    return "\n".join([line(head), line(["-" * w for w in widths]), *(line(b) for b in body)])
