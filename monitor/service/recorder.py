"""Write every processed sample of the live loop to a Rerun recording (.rrd), cheaply and without loss.

Why this shape: ``RecordingStream.log`` costs 50-90 us per call, far too much for a loop that must answer
each vehicle within a sample, while ``send_columns`` costs about 2 us per scalar when many rows go in
one call. So ``submit`` only appends the record to an in-memory deque (lock-free under the GIL, well
under a microsecond, and safe to call from a signal handler's thread), and a background writer thread
turns the pending records into one Arrow batch per vehicle and ships it with ``send_record_batch``
(one call per vehicle and flush; Rerun splits it into per-entity chunks):

* flush policy: the writer polls every ``poll_s`` (10 ms) and writes everything pending as soon as
  ``batch_size`` (256) records per vehicle seen are waiting or the oldest one has waited ``max_age_s``
  (0.5 s), so the file lags the loop by at most ~0.5 s. Per vehicle because each flush costs about
  1 ms of fixed Rerun work per vehicle: small batches over many vehicles would spend the GIL on it;
  batches grow by themselves when the writer is busy (it takes everything pending). Between vehicles
  the writer yields the GIL (``sleep(0)``) so the loop never waits behind a whole flush;
* never drop (the file): its deque is unbounded. If the writer falls behind (it has ~50x headroom: see
  ``benchmarks/bench_recorder.py``), memory grows until it catches up; nothing is discarded.
  ``close()`` writes whatever is left;
* never raise into the loop: any failure in the writer is logged once per kind (one line) and counted
  in ``stats``; only the constructor raises (``UserError``, before the loop starts) when the file
  cannot be created;
* one sink, one stream: the file is a ``FileSink``; each live viewer (``run --rerun-url``) is a
  ``LiveSink`` (``live_sinks.py``) with its own ``RecordingStream``, queue and thread, because one
  stream with several sinks goes at the pace of the slowest and a stalled viewer would hold up the file.
  ``submit`` appends to every sink's queue; a live queue is bounded (drops its oldest), the file's not.

Entity paths (units: deg, deg/s, s; vectors are split into one scalar entity per component ``<i>``)::

    /vehicle/<sysid>/measured/alpha        angle of attack, deg
    /vehicle/<sysid>/measured/q            pitch rate, deg/s
    /vehicle/<sysid>/measured/elevator     measured elevator deflection, deg (rows only when reported)
    /vehicle/<sysid>/measured/y/<i>        the output vector fed to the observer, plant units
    /vehicle/<sysid>/estimate/x_hat/<i>    state estimate at k (before the update)
    /vehicle/<sysid>/estimate/f_hat/<i>    fault estimate at k (the one used in u(k))
    /vehicle/<sysid>/command/u/<i>         command sent back for sample k
    /vehicle/<sysid>/residual/<i>          y(k) - C x_hat(k)
    /vehicle/<sysid>/timing/tau_obs        delay observed by the monitor, s (rows only when observed)
    /vehicle/<sysid>/timing/processing_ms  monitor processing time of the sample, ms
    /vehicle/<sysid>/alarm                 1.0 while the fault alarm is raised, else 0.0
    /vehicle/<sysid>/run                   0 for the vehicle's first estimator, then 1, 2, ... after restarts
    /vehicle/<sysid>/truth/x/<i>           simulator ground truth (uav/<sysid>/truth), when subscribed
    /vehicle/<sysid>/truth/f/<i>
    /vehicle/<sysid>/truth/d/<i>
    /vehicle/<sysid>/truth/tau             true delay, s (rows only when known)

Timelines: ``sample`` (sequence, k), ``time`` (duration, the sampling instant t in s) and, for the
monitor's own rows, ``wall_time`` (timestamp, receive time). Recording properties (strings) sit under
``/__properties/fault_monitor``; ``layout`` names the version of this table. ``monitor.replay`` reads
the same paths back; ``RECORDING.md`` beside this file is the user-facing copy of the table.
"""

from __future__ import annotations

import atexit
import collections
import json
import logging
import math
import operator
import platform
import threading
import time
import weakref
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any
from importlib import metadata
from pathlib import Path

import numpy as np

from monitor.errors import UserError
from monitor.service.records import SampleRecord, TruthRecord

if TYPE_CHECKING:
    from monitor.closed_loop import Gains
    from monitor.service.live_sinks import LiveSink
    from monitor.plant import Plant

__all__ = [
    "RrdRecorder",
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
    "default_blueprint",
]

log = logging.getLogger(__name__)

LAYOUT_VERSION = "1"
PROPERTY_NAME = "fault_monitor"

# Record field -> entity path below /vehicle/<sysid>/, with the scale applied on write (replay divides).
SAMPLE_SCALARS: dict[str, tuple[str, float]] = {
    "alpha": ("measured/alpha", 1.0),
    "q": ("measured/q", 1.0),
    "elevator": ("measured/elevator", 1.0),
    "tau_obs": ("timing/tau_obs", 1.0),
    "processing_s": ("timing/processing_ms", 1e3),
    "alarm": ("alarm", 1.0),
    "run": ("run", 1.0),
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


def recording_properties(plant: Plant, gains: Gains, method: str,
                         gains_source: str | None = None) -> dict[str, str]:
    """The plant and gains a recording was made with, as recording properties (matrices as JSON rows).

    For ``RrdRecorder(properties=...)``: a recording must say which model and gains produced its
    estimates, or it cannot be re-scored or reproduced later.
    """
    props = {
        "plant_name": plant.name, "plant_source": plant.source, "plant_hash": plant.digest,
        "plant_h_s": repr(plant.h), "plant_tau_s": f"[{plant.tau_min!r}, {plant.tau_max!r}]",
        "plant_unit": plant.unit,
        "gains_method": method, "gains_source": gains_source or "",
    }
    for name in ("L", "M", "K1", "K2", "K3"):
        props[f"gains_{name}"] = json.dumps(np.asarray(getattr(gains, name), dtype=float).tolist())
    return props


def default_blueprint(sysids: Iterable[int]):  # -> rerun.blueprint.Blueprint
    """The layout ``rerun FILE.rrd`` opens on: per vehicle, f_hat vs the true fault, alpha, q, u, delay."""
    import rerun.blueprint as rrb

    def vehicle(sysid: int):
        o = f"/vehicle/{sysid}"
        return rrb.Grid(
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/estimate/f_hat/**", f"{o}/truth/f/**"],
                               name=f"#{sysid} f_hat vs true fault"),
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/measured/alpha"], name=f"#{sysid} alpha (deg)"),
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/measured/q"], name=f"#{sysid} q (deg/s)"),
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/command/u/**", f"{o}/measured/elevator"],
                               name=f"#{sysid} u and elevator"),
            rrb.TimeSeriesView(origin=o, contents=[f"{o}/timing/tau_obs", f"{o}/truth/tau"],
                               name=f"#{sysid} delay (s)"),
            grid_columns=2,
            name=f"vehicle {sysid}",
        )

    ids = sorted(sysids)
    if not ids:
        root = rrb.TimeSeriesView(origin="/vehicle", name="all series")
    elif len(ids) == 1:
        root = vehicle(ids[0])
    else:
        root = rrb.Tabs(*[vehicle(s) for s in ids])
    return rrb.Blueprint(root, rrb.TimePanel(timeline="sample"), collapse_panels=False)


def _columns(records: Sequence[object], scalars: dict[str, tuple[str, float]],
             vectors: dict[str, str]) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """Yield ``(relative path, row mask, values)`` per scalar entity; a ``None`` field leaves its row out.

    The common case (no ``None``, vectors of one width) goes through one ``np.array`` call per field:
    this runs in the writer thread but holds the GIL, so its cost is taken from the loop.
    """
    n = len(records)
    everyone = np.ones(n, bool)
    names = [*scalars, *vectors]
    rows = map(operator.attrgetter(*names), records)
    fields = dict(zip(names, zip(*rows))) if n else dict.fromkeys(names, ())
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

    return pa.field(f"{entity}:Scalars:scalars", pa.list_(pa.float64()), metadata={
        "rerun:kind": "data", "rerun:entity_path": entity, "rerun:archetype": "rerun.archetypes.Scalars",
        "rerun:component": "Scalars:scalars", "rerun:component_type": "rerun.components.Scalar"})


def _record_batch(sysid: int, records: Sequence[SampleRecord | TruthRecord],
                  scalars: dict[str, tuple[str, float]], vectors: dict[str, str], wall: bool) -> Any:
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
    if wall:
        w_ns = np.round(np.array([r.wall for r in records], dtype=float) * 1e9).astype(np.int64)
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


def open_stream(application_id: str, recording_id: str, properties: dict[str, str], recording_name: str,
                attach: Callable[[Any], None]) -> Any:
    """A ``RecordingStream`` with its sink attached (``attach``), the recording properties and name sent.

    Every sink of one run gets its own stream with the same ``recording_id``, so a viewer that is shown
    the file later (or reconnects) sees one recording, not several.
    """
    import rerun as rr

    rec = rr.RecordingStream(application_id, recording_id=recording_id)
    attach(rec)
    rec.send_property(PROPERTY_NAME, rr.AnyValues(**{k: str(v) for k, v in properties.items()}))
    rec.send_recording_name(recording_name)
    return rec


class StreamWriter:
    """One Rerun sink, fed from its own queue by its own thread: the batching, the blueprint, never raising.

    Why one per sink: a ``RecordingStream`` moves at the pace of its slowest sink, so a live viewer that
    stalls must not share a stream (nor a thread, nor a queue) with the file. ``maxlen`` bounds the queue
    (the oldest records go first and are counted in ``stats["dropped"]``); ``None`` keeps every record.
    Subclasses set ``self._rec`` and decide what a failure means (``_fail_once``).
    """

    def __init__(self, label: str, *, maxlen: int | None = None, batch_size: int = 256, max_age_s: float = 0.5,
                 poll_s: float = 0.01) -> None:
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
        self._thread = threading.Thread(target=self._run, name=f"rrd-{label}", daemon=True)
        self.stats = {"submitted": 0, "written": 0, "failed": 0, "dropped": 0}

    # -- the loop's side: O(1), no locks, no I/O -------------------------------------------------------

    def put(self, rec: SampleRecord | TruthRecord) -> None:
        pending = self._pending
        if not pending:
            self._oldest = time.monotonic()
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

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
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

    def _write(self, records: list, scalars: dict[str, tuple[str, float]], vectors: dict[str, str],
               wall: bool) -> None:
        for sysid, recs in _by_sysid(records).items():
            ok = self._guard("write", lambda: self._write_vehicle(sysid, recs, scalars, vectors, wall))
            self.stats["written" if ok else "failed"] += len(recs)
            if ok:
                self._sysids.add(sysid)
            time.sleep(0)  # let the loop thread take the GIL between vehicles

    def _write_vehicle(self, sysid: int, recs: list, scalars: dict[str, tuple[str, float]],
                       vectors: dict[str, str], wall: bool) -> None:
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
        if self._guard("blueprint", lambda: self._rec.send_blueprint(default_blueprint(ids), make_active=True,
                                                                      make_default=True)):
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


class FileSink(StreamWriter):
    """The ``.rrd`` file: lossless (unbounded queue), and a write failure is the run's ``error``."""

    def __init__(self, path: Path, application_id: str, recording_id: str, properties: dict[str, str],
                 recording_name: str, **policy: Any) -> None:
        super().__init__(path.name, **policy)
        self.path = path
        self.error: str | None = None  # the first write failure, as one line (the daemon reports it)
        if self.path.is_dir() or not self.path.parent.is_dir():
            raise UserError(f"cannot write recording {self.path}: not a file in an existing directory")
        try:
            self._rec = open_stream(application_id, recording_id, properties, recording_name,
                                    lambda rec: rec.save(str(self.path), default_blueprint=default_blueprint(())))
        except (OSError, RuntimeError, ValueError) as exc:
            raise UserError(f"cannot write recording {self.path}: {exc}") from exc
        self._thread.start()

    def _after_drain(self, n: int) -> None:
        # Rerun writes the file from its own thread and reports a failure (disk full) only on flush: flush
        # here, in the writer thread, so that a failure is known within one batch, not at close
        if self.error is None and not self._guard(f"writing {self.path} (disk full or file removed?)",
                                                  lambda: self._rec.flush(timeout_sec=5.0)):
            self.stats["failed"] += n

    def _fail_once(self, kind: str, message: str) -> None:
        if self.error is None:
            self.error = f"{kind}: {message}"
        super()._fail_once(kind, message)

    def close(self, timeout_s: float) -> None:
        """Stop the writer, write what is left, the blueprint and the footer (in the calling thread)."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        if self._thread.is_alive():
            self._fail_once("close", f"writer thread still busy after {timeout_s} s")
        self._drain()
        self._update_blueprint(force=True)
        self._guard("close", self._finish)

    def _finish(self) -> None:
        self._rec.flush()
        self._rec.disconnect()  # drops the file sink: writes the footer


class RrdRecorder:
    """Buffered, never-raising fan-out of ``SampleRecord``/``TruthRecord`` to a ``.rrd`` file and live viewers.

    Every sink gets every record and the blueprint through its own stream, queue and thread: the file
    (``path``) is lossless; each live viewer (``live``: ``rerun+http://HOST:PORT/proxy`` URLs, see
    ``monitor.service.live_sinks``) has a bounded queue, so a slow or vanished viewer costs its own
    oldest records, never the file's rows nor the loop's time.

    ``submit``/``submit_truth`` may be called from any thread (the loop, a Zenoh callback); ``close``
    is idempotent and safe from a signal handler: it stops the writers, writes what is left, the
    blueprint and the footer. It is also registered with ``atexit`` so a normal interpreter exit
    leaves a complete file even when the caller forgets.
    """

    def __init__(self, path: str | Path | None, application_id: str = "fault-monitor",
                 properties: dict[str, str] | None = None, *, batch_size: int = 256, max_age_s: float = 0.5,
                 poll_s: float = 0.01, recording_name: str | None = None, live: Sequence[str] = ()) -> None:
        import uuid

        if live:  # every address checked before the file sink's thread starts
            from monitor.service.live_sinks import LiveSink, parse_viewer_url

            for url in live:
                parse_viewer_url(url)
        self.path = Path(path) if path is not None else None
        props = {"layout": LAYOUT_VERSION, **software_versions(), **(properties or {})}
        name = recording_name or f"{application_id} {self.path.stem if self.path else 'live'}"
        recording_id = str(uuid.uuid4())
        self._file = None if self.path is None else FileSink(
            self.path, application_id, recording_id, props, name, batch_size=batch_size, max_age_s=max_age_s,
            poll_s=poll_s)
        self.live: list[LiveSink] = []
        if live:
            self.live = [LiveSink(url, application_id, recording_id, props, name) for url in live]
        self._sinks: tuple[StreamWriter, ...] = ((self._file,) if self._file else ()) + tuple(self.live)
        self._closed = False
        self._close_lock = threading.Lock()
        atexit.register(_close_ref, weakref.ref(self))

    @property
    def error(self) -> str | None:
        """The file's first write failure as one line, else ``None`` (live viewers only ever warn)."""
        return self._file.error if self._file else None

    @property
    def stats(self) -> dict[str, int]:
        """The file's counters (``submitted``, ``written``, ``failed``); live sinks keep their own."""
        return self._file.stats if self._file else {"submitted": 0, "written": 0, "failed": 0, "dropped": 0}

    @property
    def _rec(self) -> Any:
        return self._file._rec if self._file else None

    # -- the loop's side: O(1) per sink, no locks, no I/O ------------------------------------------------

    def submit(self, rec: SampleRecord) -> None:
        """Queue one processed sample; it will be in the file after the next flush or ``close()``."""
        self._queue(rec)

    def submit_truth(self, rec: TruthRecord) -> None:
        """Queue one ground-truth sample from the simulator (``uav/<sysid>/truth``)."""
        self._queue(rec)

    def _queue(self, rec: SampleRecord | TruthRecord) -> None:
        if self._closed:
            if self._file is not None:
                self._file._fail_once("closed", "record submitted after close() is not written")
            return
        for sink in self._sinks:
            sink.put(rec)

    def _drain(self) -> None:
        """Write the file's pending records now (the benchmark times the writer's step with it)."""
        if self._file is not None:
            self._file._drain()

    # -- shutdown -------------------------------------------------------------------------------------

    def close(self, timeout_s: float = 10.0, live_timeout_s: float = 3.0) -> None:
        """Write everything submitted so far to every sink. Idempotent, never raises.

        The live sinks finish in their own threads while the file is closed here; a viewer that has not
        taken the rest after ``live_timeout_s`` more is left behind (it must not hold up the exit).
        """
        if not self._close_lock.acquire(blocking=False):
            return  # another thread (or an interrupted frame of this one) is closing already
        try:
            if self._closed:
                return
            self._closed = True
            for sink in self.live:
                sink.close()
            if self._file is not None:
                self._file.close(timeout_s)
            deadline = time.monotonic() + live_timeout_s
            for sink in self.live:
                sink.join(max(0.0, deadline - time.monotonic()))
        finally:
            self._close_lock.release()

    def __enter__(self) -> RrdRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _close_ref(ref: weakref.ref[RrdRecorder]) -> None:
    rec = ref()
    if rec is not None:
        rec.close()
