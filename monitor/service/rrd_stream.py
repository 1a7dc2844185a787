"""The recording's layout and the stream writer every sink shares (the .rrd file and each live viewer).

Why a module of its own: the file sink (``monitor.service.recorder``) and the live viewers
(``monitor.service.live_sinks``) are both a ``StreamWriter`` over this one entity layout; with the layout
here, each of them imports it and neither imports the other. The layout itself (entity paths, timelines,
properties) is documented in ``monitor.service.recorder`` and ``RECORDING.md``.
"""

from __future__ import annotations

import collections
import functools
import json
import logging
import math
import operator
import platform
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from importlib import metadata
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from monitor.service.records import SampleRecord, TruthRecord

if TYPE_CHECKING:
    from monitor.model.closed_loop import Gains
    from monitor.model.plant import Plant
    from monitor.service.fleet_file import EnvelopeModel

__all__ = [
    "StreamWriter",
    "open_stream",
    "LAYOUT_VERSION",
    "PROPERTY_NAME",
    "SAMPLE_SCALARS",
    "SAMPLE_VECTORS",
    "TRUTH_SCALARS",
    "TRUTH_VECTORS",
    "software_versions",
    "recording_properties",
    "envelope_properties",
    "default_blueprint",
]

log = logging.getLogger(
    "monitor.service.recorder"
)  # one logger for the whole recording: its messages predate the split

LAYOUT_VERSION = "1"
PROPERTY_NAME = "fault_monitor"

# Record field -> entity path below /vehicle/<sysid>/, with the scale applied on write (replay divides).
SAMPLE_SCALARS: dict[str, tuple[str, float]] = {
    "alpha": ("measured/alpha", 1.0),
    "q": ("measured/q", 1.0),
    "elevator": ("measured/elevator", 1.0),
    "tau_obs": ("timing/tau_obs", 1.0),
    "processing_s": ("timing/processing_ms", 1e3),
    "shed": ("timing/shed", 1.0),
    "alarm": ("alarm", 1.0),
    "run": ("run", 1.0),
    "point": ("envelope/point", 1.0),  # envelope models only: a single-point model's rows leave them out
    "inside": ("envelope/inside", 1.0),
    "served": ("group/served", 1.0),  # a monitor group only: 1 answered by this member, 0 kept warm
}
SAMPLE_VECTORS: dict[str, str] = {
    "y": "measured/y",
    "x_hat": "estimate/x_hat",
    "f_hat": "estimate/f_hat",
    "u": "command/u",
    "residual": "residual",
}
TRUTH_SCALARS: dict[str, tuple[str, float]] = {"tau": ("truth/tau", 1.0)}
TRUTH_VECTORS: dict[str, str] = {"x": "truth/x", "f": "truth/f", "d": "truth/d"}

TIMELINES = ("sample", "time", "wall_time")
BLUEPRINT_EVERY_S = 10.0

_DISTRIBUTIONS = {
    "fault_monitor_version": "uav-fault-monitor",
    "rerun_sdk_version": "rerun-sdk",
    "pymavlink_version": "pymavlink",
    "zenoh_version": "eclipse-zenoh",
    "numpy_version": "numpy",
}


def software_versions() -> dict[str, str]:
    """Versions worth keeping with a recording: ``.rrd`` files only promise to open in the next Rerun."""
    out = {"python_version": platform.python_version()}
    for key, dist in _DISTRIBUTIONS.items():
        try:
            out[key] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[key] = "not installed"
    return out


def recording_properties(plant: Plant, gains: Gains, method: str, gains_source: str | None = None) -> dict[str, str]:
    """The plant and gains a recording was made with, as recording properties (matrices as JSON rows).

    For ``RrdRecorder(properties=...)``: a recording must say which model and gains produced its
    estimates, or it cannot be re-scored or reproduced later.
    """
    props = {
        "plant_name": plant.name,
        "plant_source": plant.source,
        "plant_hash": plant.digest,
        "plant_h_s": repr(plant.h),
        "plant_tau_s": f"[{plant.tau_min!r}, {plant.tau_max!r}]",
        "plant_unit": plant.unit,
        "gains_method": method,
        "gains_source": gains_source or "",
    }
    for name in ("L", "M", "K1", "K2", "K3"):
        props[f"gains_{name}"] = json.dumps(np.asarray(getattr(gains, name), dtype=float).tolist())
    return props


def envelope_properties(env: EnvelopeModel) -> dict[str, str]:
    """An envelope model's properties: its name and hash, the schedule, the points' names in the order that
    ``envelope/point`` indexes, their places and operating points (JSON), and the switching rule."""
    from monitor.model.scheduling import HYSTERESIS

    envelope = env.envelope
    return {
        "envelope": envelope.name,
        "envelope_hash": envelope.digest,
        "envelope_schedule": json.dumps(list(envelope.schedule)),
        "envelope_points": json.dumps(list(envelope.names)),
        "envelope_at": json.dumps([p.at for p in envelope.points]),
        "envelope_operating_points": json.dumps(
            {name: m.signals.operating_point for name, m in zip(envelope.names, env.points, strict=True)}
        ),
        "envelope_switching": f"nearest point, hysteresis {HYSTERESIS:.0%} of the spacing",
    }


def default_blueprint(sysids: Iterable[int]):  # -> rerun.blueprint.Blueprint
    """The layout ``rerun FILE.rrd`` opens on: per vehicle, f_hat vs the true fault, alpha, q, u, delay."""
    import rerun.blueprint as rrb

    def vehicle(sysid: int):
        o = f"/vehicle/{sysid}"
        return rrb.Grid(
            rrb.TimeSeriesView(
                origin=o, contents=[f"{o}/estimate/f_hat/**", f"{o}/truth/f/**"], name=f"#{sysid} f_hat vs true fault"
            ),
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/measured/alpha"], name=f"#{sysid} alpha (deg)"),
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/measured/q"], name=f"#{sysid} q (deg/s)"),
            rrb.TimeSeriesView(
                origin=o, contents=[f"{o}/command/u/**", f"{o}/measured/elevator"], name=f"#{sysid} u and elevator"
            ),
            rrb.TimeSeriesView(
                origin=o, contents=[f"{o}/timing/tau_obs", f"{o}/truth/tau"], name=f"#{sysid} delay (s)"
            ),
            grid_columns=2,
            name=f"vehicle {sysid}",
        )

    ids = sorted(sysids)
    root: rrb.Container | rrb.View
    if not ids:
        root = rrb.TimeSeriesView(origin="/vehicle", name="all series")
    elif len(ids) == 1:
        root = vehicle(ids[0])
    else:
        root = rrb.Tabs(*[vehicle(s) for s in ids])
    return rrb.Blueprint(root, rrb.TimePanel(timeline="sample"), collapse_panels=False)


def _columns(
    records: Sequence[object], scalars: dict[str, tuple[str, float]], vectors: dict[str, str]
) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """Yield ``(relative path, row mask, values)`` per scalar entity; a ``None`` field leaves its row out.

    The common case (no ``None``, vectors of one width) goes through one ``np.array`` call per field:
    this runs in the writer thread but holds the GIL, so its cost is taken from the loop.
    """
    n = len(records)
    everyone = np.ones(n, bool)
    names = [*scalars, *vectors]
    rows = map(operator.attrgetter(*names), records)
    fields = dict(zip(names, zip(*rows, strict=True), strict=True)) if n else dict.fromkeys(names, ())
    for field, (path, scale) in scalars.items():
        raw = fields[field]
        if None not in raw:
            yield path, everyone, np.array(raw, dtype=float) * scale
            continue
        mask = np.fromiter((v is not None for v in raw), bool, n)
        values = np.fromiter((float(v) * scale if v is not None else 0.0 for v in raw), float, n)
        yield path, mask, values
    for field, path in vectors.items():
        raw = fields[field]
        widths = set(map(len, raw))
        if len(widths) == 1:
            table = np.array(raw, dtype=float).reshape(n, -1)
            for i in range(table.shape[1]):
                yield f"{path}/{i}", everyone, table[:, i]
            continue
        for i in range(max(widths, default=0)):
            mask = np.fromiter((len(v) > i for v in raw), bool, n)
            values = np.fromiter((float(v[i]) if len(v) > i else 0.0 for v in raw), float, n)
            yield f"{path}/{i}", mask, values


def _scalar_field(entity: str) -> Any:
    import pyarrow as pa

    return pa.field(
        f"{entity}:Scalars:scalars",
        pa.list_(pa.float64()),
        metadata={
            "rerun:kind": "data",
            "rerun:entity_path": entity,
            "rerun:archetype": "rerun.archetypes.Scalars",
            "rerun:component": "Scalars:scalars",
            "rerun:component_type": "rerun.components.Scalar",
        },
    )


def _record_batch(
    sysid: int,
    records: Sequence[SampleRecord | TruthRecord],
    scalars: dict[str, tuple[str, float]],
    vectors: dict[str, str],
    wall: bool,
) -> Any:
    """One vehicle's pending rows as ONE ``pyarrow.RecordBatch``: a column per entity, shared timelines.

    Why not ``send_columns`` per entity: its fixed cost (~150-250 us a call, most of it building the
    index and component columns in Python) times ~15 entities per vehicle would hold the GIL for
    milliseconds per flush; ``send_record_batch`` splits one batch into per-entity chunks in Rust.
    A ``None`` field is a null row, which Rerun stores as "not logged at this sample".
    """
    import pyarrow as pa

    n = len(records)
    k = np.array([r.k for r in records], dtype=np.int64)
    t_ns = np.round(np.array([r.t for r in records], dtype=float) * 1e9).astype(np.int64)
    arrays = [pa.array(k), pa.array(t_ns, pa.duration("ns"))]
    fields = [pa.field("sample", pa.int64()), pa.field("time", pa.duration("ns"))]
    if wall:  # sample records: only they carry the receive time
        samples = cast("Sequence[SampleRecord]", records)
        w_ns = np.round(np.array([r.wall for r in samples], dtype=float) * 1e9).astype(np.int64)
        arrays.append(pa.array(w_ns, pa.timestamp("ns")))
        fields.append(pa.field("wall_time", pa.timestamp("ns")))
    offsets = pa.array(np.arange(n + 1, dtype=np.int32))
    for path, mask, values in _columns(records, scalars, vectors):
        if not mask.any():
            continue
        nulls = None if mask.all() else pa.array(~mask)
        arrays.append(pa.ListArray.from_arrays(offsets, pa.array(values, pa.float64()), mask=nulls))
        fields.append(_scalar_field(f"/vehicle/{sysid}/{path}"))
    return pa.RecordBatch.from_arrays(arrays, schema=pa.schema(fields))


def _by_sysid(records: Iterable[SampleRecord | TruthRecord]) -> dict[int, list]:
    groups: dict[int, list] = {}
    for r in records:
        groups.setdefault(int(r.sysid), []).append(r)
    return groups


def open_stream(
    application_id: str,
    recording_id: str,
    properties: dict[str, str],
    recording_name: str,
    attach: Callable[[Any], None],
) -> Any:
    """A ``RecordingStream`` with its sink attached (``attach``), the recording properties and name sent.

    Every sink of one run gets its own stream with the same ``recording_id``, so a viewer that is shown
    the file later (or reconnects) sees one recording, not several.
    """
    import rerun as rr

    rec = rr.RecordingStream(application_id, recording_id=recording_id)
    attach(rec)
    rec.send_property(
        PROPERTY_NAME, rr.AnyValues(drop_untyped_nones=True, **{k: str(v) for k, v in properties.items()})
    )
    rec.send_recording_name(recording_name)
    return rec


class StreamWriter:
    """One Rerun sink, fed from its own queue by its own thread: the batching, the blueprint, never raising.

    Why one per sink: a ``RecordingStream`` moves at the pace of its slowest sink, so a live viewer that
    stalls must not share a stream (nor a thread, nor a queue) with the file. ``maxlen`` bounds the queue
    (the oldest records go first and are counted in ``stats["dropped"]``); ``None`` keeps every record.
    Subclasses set ``self._rec`` and decide what a failure means (``_fail_once``).
    """

    def __init__(
        self,
        label: str,
        *,
        maxlen: int | None = None,
        batch_size: int = 256,
        max_age_s: float = 0.5,
        poll_s: float = 0.01,
    ) -> None:
        self.label = label
        self.batch_size = batch_size
        self.max_age_s = max_age_s
        self.poll_s = poll_s
        self._rec: Any = None
        self._pending: collections.deque[SampleRecord | TruthRecord] = collections.deque(maxlen=maxlen)
        self._oldest: float | None = None  # monotonic time of the oldest pending record (approximate)
        self._sysids: set[int] = set()
        self._blueprint_ids: frozenset[int] = frozenset()
        self._blueprint_at = -math.inf  # monotonic time of the last blueprint sent
        self._failures: set[str] = set()
        self._stop = threading.Event()
        self._wake = threading.Event()  # set by the first record after a flush, and by ``stop``
        self._thread = threading.Thread(target=self._run, name=f"rrd-{label}", daemon=True)
        self.stats = {"submitted": 0, "written": 0, "failed": 0, "dropped": 0}

    # -- the loop's side: O(1), no locks, no I/O -------------------------------------------------------

    def put(self, rec: SampleRecord | TruthRecord) -> None:
        pending = self._pending
        if not pending:
            self._oldest = time.monotonic()
            self._wake.set()  # once per flush, not per record: the writer sleeps while nothing is pending
        elif len(pending) == pending.maxlen:
            self.stats["dropped"] += 1  # the deque drops its oldest record on this append
        pending.append(rec)
        self.stats["submitted"] += 1

    # -- the writer's side ------------------------------------------------------------------------------

    def _due(self) -> bool:
        if len(self._pending) >= self.batch_size * max(1, len(self._sysids)):
            return True
        oldest = self._oldest
        return bool(self._pending) and oldest is not None and time.monotonic() - oldest >= self.max_age_s

    def stop(self) -> None:
        """Ask the writer thread to finish (it wakes at once)."""
        self._stop.set()
        self._wake.set()

    def _sleep(self, timeout: float | None) -> bool:
        """Wait until woken (a first record, ``stop``) or ``timeout``; returns whether to stop."""
        self._wake.wait(timeout)
        self._wake.clear()
        return self._stop.is_set()

    def _run(self) -> None:
        # nothing pending: sleep until the first record (no polling while idle); then check every poll_s
        while not self._sleep(self.poll_s if self._pending else None):
            if self._due():
                self._drain()

    def _drain(self) -> None:
        """Take everything pending (other threads may keep appending) and write it, never raising."""
        self._oldest = time.monotonic()
        batch = [self._pending.popleft() for _ in range(len(self._pending))]  # a snapshot: producers go on
        if not batch:
            return
        samples = [r for r in batch if isinstance(r, SampleRecord)]
        truths = [r for r in batch if isinstance(r, TruthRecord)]
        self._write(samples, SAMPLE_SCALARS, SAMPLE_VECTORS, wall=True)
        self._write(truths, TRUTH_SCALARS, TRUTH_VECTORS, wall=False)
        self._update_blueprint(force=False)
        self._after_drain(len(batch))

    def _after_drain(self, n: int) -> None:
        """Hook: what a sink checks once a batch of ``n`` records went out."""

    def _write(self, records: list, scalars: dict[str, tuple[str, float]], vectors: dict[str, str], wall: bool) -> None:
        for sysid, recs in _by_sysid(records).items():
            # called at once, in this iteration; bound explicitly all the same
            ok = self._guard("write", functools.partial(self._write_vehicle, sysid, recs, scalars, vectors, wall))
            self.stats["written" if ok else "failed"] += len(recs)
            if ok:
                self._sysids.add(sysid)
            time.sleep(0)  # let the loop thread take the GIL between vehicles

    def _write_vehicle(
        self, sysid: int, recs: list, scalars: dict[str, tuple[str, float]], vectors: dict[str, str], wall: bool
    ) -> None:
        batch = _record_batch(sysid, recs, scalars, vectors, wall)
        self._rec.send_record_batch(batch, index=[name for name in TIMELINES if name in batch.schema.names])

    def _update_blueprint(self, force: bool) -> None:
        """Re-send the default layout when vehicles joined: at once for the first, then at most every
        ``BLUEPRINT_EVERY_S`` (each copy stays in the file) and at ``close()``."""
        ids = frozenset(self._sysids)
        if ids == self._blueprint_ids:
            return
        if not force and self._blueprint_ids and time.monotonic() - self._blueprint_at < BLUEPRINT_EVERY_S:
            return
        if self._guard(
            "blueprint", lambda: self._rec.send_blueprint(default_blueprint(ids), make_active=True, make_default=True)
        ):
            self._blueprint_ids, self._blueprint_at = ids, time.monotonic()

    def _guard(self, kind: str, fn: Callable[[], None]) -> bool:
        """Run ``fn``; on failure log one line per kind (not per batch) and report False."""
        try:
            fn()
            return True
        except Exception as exc:  # noqa: BLE001 - a recorder must never take the loop down
            self._fail_once(kind, f"{type(exc).__name__}: {exc}")
            return False

    def _fail_once(self, kind: str, message: str) -> None:
        if kind not in self._failures:
            self._failures.add(kind)
            log.error("rrd recorder %s failed (%s); the loop goes on, see recorder stats", kind, message)
