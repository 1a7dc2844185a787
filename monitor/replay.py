"""Read a monitor recording (.rrd) back without a viewer and score it: the engine of ``fault-monitor replay``.

Why our own reader rather than Rerun's dataframe API: in rerun-sdk 0.41 that API needs the ``catalog``
extra (datafusion, pandas); ``rerun.chunk.RrdReader`` + pyarrow ship with the base wheel, and the
entity layout is ours (``monitor.service.rrd_stream``), so rebuilding the ``SampleRecord``/``TruthRecord``
rows is a small, exact inverse of what the recorder wrote.

Where the fault comes from, in order: the truth stream recorded beside the estimates (``truth/f``),
else a fault SPEC given by the caller (``--fault bias:2@20``), else nothing (then settling and the
estimation error are ``None``). The scores are those of ``monitor.checks.metrics`` on the fault's first
component (the elevator fault).
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from monitor.checks import metrics
from monitor.errors import UserError
from monitor.service.rrd_stream import (
    PROPERTY_NAME,
    SAMPLE_SCALARS,
    SAMPLE_VECTORS,
    TRUTH_SCALARS,
    TRUTH_VECTORS,
)
from monitor.service.records import SampleRecord, TruthRecord

__all__ = ["VehicleSeries", "Recording", "load_recording", "analyse", "analyse_vehicle", "SETTLING_TOL"]

SETTLING_TOL = 0.05
_VEHICLE_RE = re.compile(r"^/vehicle/(\d+)/(.+)$")


@dataclass
class VehicleSeries:
    """One vehicle's rows, sorted by ``k``: what the monitor processed and, when recorded, the truth."""

    sysid: int
    samples: list[SampleRecord] = field(default_factory=list)
    truth: list[TruthRecord] = field(default_factory=list)


@dataclass
class Recording:
    path: Path
    application_id: str
    properties: dict[str, str]
    vehicles: dict[int, VehicleSeries]
    has_footer: bool


# -- reading ------------------------------------------------------------------------------------------


def _layout() -> dict[str, tuple[str, str, int | None, float]]:
    """Relative entity path -> (kind, field, component index or None, scale), inverted from the recorder."""
    out: dict[str, tuple[str, str, int | None, float]] = {}
    tables = (("sample", SAMPLE_SCALARS, SAMPLE_VECTORS), ("truth", TRUTH_SCALARS, TRUTH_VECTORS))
    for kind, scalars, vectors in tables:
        for name, (path, scale) in scalars.items():
            out[path] = (kind, name, None, scale)
        for name, path in vectors.items():
            out[path] = (kind, name, -1, 1.0)  # -1: the component index follows in the path
    return out


_LAYOUT = _layout()


def _locate(rel: str) -> tuple[str, str, int | None, float] | None:
    if rel in _LAYOUT:
        return _LAYOUT[rel]
    prefix, _, index = rel.rpartition("/")
    hit = _LAYOUT.get(prefix)
    if hit is None or hit[2] != -1 or not index.isdigit():
        return None
    return hit[0], hit[1], int(index), 1.0


def _seconds(column: Any) -> np.ndarray:
    """A duration/timestamp column (ns) as float seconds, without datetime objects on the way."""
    import pyarrow as pa

    return column.cast(pa.int64()).to_numpy(zero_copy_only=False) / 1e9


def _scalars(column: Any) -> tuple[np.ndarray, np.ndarray]:
    """A ``Scalars:scalars`` column (a list of one float per row) as (row has a value, float values).

    A null or empty row means "not logged at this sample" (e.g. no elevator reading): it is skipped.
    """
    import pyarrow.compute as pc

    has_value = pc.fill_null(pc.greater(pc.list_value_length(column), 0), False)
    present = has_value.to_numpy(zero_copy_only=False).astype(bool)
    values = np.full(len(column), math.nan)
    if present.any():
        values[present] = pc.list_element(column.filter(has_value), 0).to_numpy(zero_copy_only=False)
    return present, values


def _read_chunks(path: Path) -> tuple[Any, list[Any], bool]:
    """Open the file: (store entry, chunks, has_footer); every failure becomes one ``UserError`` line."""
    from rerun.chunk import RrdReader

    if not path.is_file():
        raise UserError(f"{path}: no such recording file")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            reader = RrdReader(path)
            stores = reader.recordings()
            if not stores:
                raise UserError(f"{path}: no recording inside (not a fault-monitor .rrd)")
            chunks = reader.stream(store=stores[0]).to_chunks()
    except (RuntimeError, ValueError, OSError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        hint = ""
        if "exceeds file size" in first or "footer" in first:
            hint = f" (truncated: writer killed? salvage with `rerun rrd optimize {path} -o FIXED.rrd`)"
        raise UserError(f"{path}: not a readable .rrd recording: {first}{hint}") from None
    has_footer = not any("no footer" in str(w.message) for w in caught)
    return stores[0], chunks, has_footer


def _properties(chunk: Any) -> dict[str, str]:
    batch = chunk.to_record_batch()
    out = {}
    for name in batch.schema.names:
        if name.startswith("rerun.controls"):
            continue
        values = batch.column(name).to_pylist()
        if values and values[-1]:
            out[name] = str(values[-1][0])
    return out


@dataclass
class _Column:
    """One chunk of one scalar entity: which record field it fills, and its rows."""

    field: str
    index: int | None  # component of a vector field, None for a scalar field
    k: np.ndarray
    t: np.ndarray
    wall: np.ndarray | None
    values: np.ndarray  # already divided by the recorder's scale


def _column(chunk: Any, field: str, index: int | None, scale: float) -> _Column | None:
    batch = chunk.to_record_batch()
    names = batch.schema.names
    if "sample" not in names or "Scalars:scalars" not in names:
        return None
    present, values = _scalars(batch.column("Scalars:scalars"))
    k = batch.column("sample").to_numpy(zero_copy_only=False).astype(np.int64)[present]
    t = _seconds(batch.column("time"))[present] if "time" in names else np.full(k.size, math.nan)
    wall = _seconds(batch.column("wall_time"))[present] if "wall_time" in names else None
    return _Column(field, index, k, t, wall, values[present] / scale)


_OPTIONAL = {"elevator", "tau_obs", "tau"}  # None when not recorded; other missing scalars read as NaN


def _assemble(cls: type, sysid: int, columns: list[_Column]) -> list[Any]:
    """Align every column of one vehicle and build one ``cls`` record per row.

    The monitor's rows are aligned on their receive time (``wall_time``), unique per processed sample, so
    a vehicle that restarted (k starting again) keeps both runs; rows without one (the truth) align on k.
    """
    by_wall = all(c.wall is not None for c in columns)
    keys = np.unique(np.concatenate([c.wall if by_wall else c.k for c in columns]))
    n = keys.size
    ks = np.zeros(n, np.int64)
    for c in columns:
        ks[np.searchsorted(keys, c.wall if by_wall else c.k)] = c.k
    per_row: dict[str, list[Any]] = {"sysid": [sysid] * n, "k": ks.tolist()}
    t, wall = np.full(n, math.nan), np.full(n, math.nan)
    scalars: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    vectors: dict[str, dict[int, np.ndarray]] = {}
    for c in columns:
        pos = np.searchsorted(keys, c.wall if by_wall else c.k)
        t[pos] = c.t
        if c.wall is not None:
            wall[pos] = c.wall
        if c.index is None:
            values, has = scalars.setdefault(c.field, (np.full(n, math.nan), np.zeros(n, bool)))
            values[pos], has[pos] = c.values, True
        else:
            vectors.setdefault(c.field, {}).setdefault(c.index, np.full(n, math.nan))[pos] = c.values
    per_row.update(t=t.tolist(), wall=wall.tolist())
    for name, (values, has) in scalars.items():
        if name == "alarm":
            per_row[name] = (has & (values >= 0.5)).tolist()
        elif name == "run":
            per_row[name] = [int(v) if h else 0 for v, h in zip(values.tolist(), has.tolist())]
        elif name in _OPTIONAL:
            per_row[name] = [v if h else None for v, h in zip(values.tolist(), has.tolist())]
        else:
            per_row[name] = values.tolist()
    for name, comps in vectors.items():
        width = max(comps) + 1
        table = np.full((n, width), math.nan)
        for i, values in comps.items():
            table[:, i] = values
        per_row[name] = table.tolist()
    order = [f.name for f in dataclasses.fields(cls)]
    for name in order:
        if name not in per_row:
            per_row[name] = _absent(name, n)
    return [cls(*row) for row in zip(*(per_row[name] for name in order))]


def _absent(name: str, n: int) -> list[Any]:
    """The per-row value of a field that has no entity at all in the file (e.g. never measured)."""
    if name in _OPTIONAL:
        return [None] * n
    if name in SAMPLE_VECTORS or name in TRUTH_VECTORS:
        return [[] for _ in range(n)]
    if name == "run":
        return [0] * n
    return [False] * n if name == "alarm" else [math.nan] * n


def load_recording(path: str | Path) -> Recording:
    """Rebuild every vehicle's rows from a recording. ``UserError`` for a missing, corrupt or foreign file."""
    path = Path(path)
    store, chunks, has_footer = _read_chunks(path)
    properties: dict[str, str] = {}
    columns: dict[tuple[str, int], list[_Column]] = {}
    for chunk in chunks:
        entity = chunk.entity_path
        if chunk.is_static:
            if entity == f"/__properties/{PROPERTY_NAME}":
                properties.update(_properties(chunk))
            continue
        match = _VEHICLE_RE.match(entity)
        where = _locate(match.group(2)) if match else None
        column = _column(chunk, *where[1:]) if where else None
        if column is not None and column.k.size:
            columns.setdefault((where[0], int(match.group(1))), []).append(column)
    if not columns and not properties:
        raise UserError(f"{path}: a Rerun recording, but not written by fault-monitor (no /vehicle/ data)")
    vehicles: dict[int, VehicleSeries] = {}
    for (kind, sysid), cols in sorted(columns.items()):
        series = vehicles.setdefault(sysid, VehicleSeries(sysid))
        if kind == "sample":
            series.samples = _assemble(SampleRecord, sysid, cols)
        else:
            series.truth = _assemble(TruthRecord, sysid, cols)
    return Recording(path, store.application_id, properties, dict(sorted(vehicles.items())), has_footer)


# -- scoring --------------------------------------------------------------------------------------------


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
    stop = None if None in ends else max(ends)  # an intermittent fault is scored on its episode
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


def analyse_vehicle(series: VehicleSeries, fault_spec: str | None = None,
                    tol: float = SETTLING_TOL) -> dict[str, Any]:
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
        settling = metrics.settling_steps(k[known], f_hat[known], fault.f[known], onset, fault.size, tol,
                                          fault.stop)
    rms_ef = rms_ef_post = None
    if fault and known.any():
        rms_ef = metrics.rms_error(k[known], f_hat[known], fault.f[known])
        if onset is not None:
            rms_ef_post = metrics.rms_error(k[known], f_hat[known], fault.f[known], start=onset)
    t_of = dict(zip(k.tolist(), t.tolist()))
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
        "detection_steps": None if detected is None else detected - onset,
        "detection_s": _times(None if detected is None else detected - onset, h),
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
        "peak_q": metrics.peak_abs([r.q for r in s]),
        "tau_obs_s": metrics.percentiles([r.tau_obs for r in s if r.tau_obs is not None]),
        "tau_true_s": metrics.percentiles([r.tau for r in series.truth if r.tau is not None]),
        "processing_ms": metrics.percentiles(processing),
        "truth_samples": len(series.truth),
    }


def _worst(values: list[Any]) -> Any:
    """Fleet summary of a lower-is-better score: None if any vehicle has None (never happened), else max."""
    return None if not values or any(v is None for v in values) else max(values)


def analyse(recording: Recording, sysid: int | None = None, fault_spec: str | None = None,
            tol: float = SETTLING_TOL) -> dict[str, Any]:
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
    per = {s: analyse_vehicle(v, fault_spec, tol) for s, v in vehicles.items()}
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
        out.update({
            "samples": sum(r["samples"] for r in rows),
            "false_alarms": (None if any(r["false_alarms"] is None for r in rows)
                             else sum(r["false_alarms"] for r in rows)),
            "peak_alpha": max((r["peak_alpha"] for r in rows if r["peak_alpha"] is not None), default=None),
            "rms_ef": max((r["rms_ef"] for r in rows if r["rms_ef"] is not None), default=None),
            "settling_steps": _worst([r["settling_steps"] for r in faulty]),
            "detection_steps": _worst([r["detection_steps"] for r in faulty]),
        })
    out["vehicles"] = {str(s): r for s, r in per.items()}
    return out
