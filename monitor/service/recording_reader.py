"""Read a monitor recording (.rrd) back without a viewer: every vehicle's rows, as the recorder wrote them.

Why our own reader rather than Rerun's dataframe API: in rerun-sdk 0.41 that API needs the ``catalog``
extra (datafusion, pandas); ``rerun.chunk.RrdReader`` + pyarrow ship with the base wheel, and the
entity layout is ours (``monitor.service.rrd_stream``), so rebuilding the ``SampleRecord``/``TruthRecord``
rows is a small, exact inverse of what the recorder wrote. Scoring the rows is ``monitor.scoring``'s job.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import UserError
from monitor.service.records import SampleRecord, TruthRecord
from monitor.service.rrd_stream import (
    PROPERTY_NAME,
    SAMPLE_SCALARS,
    SAMPLE_VECTORS,
    TRUTH_SCALARS,
    TRUTH_VECTORS,
)

__all__ = ["VehicleSeries", "Recording", "load_recording"]

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

    @property
    def envelope_points(self) -> list[str] | None:
        """An envelope model's points, in the order ``SampleRecord.point`` indexes; None for one plant."""
        raw = self.properties.get("envelope_points")
        if not raw:
            return None
        try:
            names = json.loads(raw)
        except ValueError:
            return None
        return [str(n) for n in names] if isinstance(names, list) else None


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


# None when not recorded; other missing scalars NaN
_OPTIONAL = {"elevator", "tau_obs", "tau", "point", "inside", "served"}


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
        ks[np.searchsorted(keys, c.wall if by_wall and c.wall is not None else c.k)] = c.k
    per_row: dict[str, list[Any]] = {"sysid": [sysid] * n, "k": ks.tolist()}
    t, wall = np.full(n, math.nan), np.full(n, math.nan)
    scalars: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    vectors: dict[str, dict[int, np.ndarray]] = {}
    for c in columns:
        pos = np.searchsorted(keys, c.wall if by_wall and c.wall is not None else c.k)
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
        elif name in ("run", "shed"):
            per_row[name] = [int(v) if h else 0 for v, h in zip(values.tolist(), has.tolist(), strict=True)]
        elif name == "point":
            per_row[name] = [int(round(v)) if h else None for v, h in zip(values.tolist(), has.tolist(), strict=True)]
        elif name in ("inside", "served"):
            per_row[name] = [bool(v >= 0.5) if h else None for v, h in zip(values.tolist(), has.tolist(), strict=True)]
        elif name in _OPTIONAL:
            per_row[name] = [v if h else None for v, h in zip(values.tolist(), has.tolist(), strict=True)]
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
    return [cls(*row) for row in zip(*(per_row[name] for name in order), strict=True)]


def _absent(name: str, n: int) -> list[Any]:
    """The per-row value of a field that has no entity at all in the file (e.g. never measured)."""
    if name in _OPTIONAL:
        return [None] * n
    if name in SAMPLE_VECTORS or name in TRUTH_VECTORS:
        return [[] for _ in range(n)]
    if name in ("run", "shed"):  # a recording from before shedding was counted: none shed
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
        if match is None or where is None:
            continue
        column = _column(chunk, *where[1:])
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
