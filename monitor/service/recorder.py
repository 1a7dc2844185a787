"""Write every processed sample of the live loop to a Rerun recording (.rrd), cheaply and without loss.

Why this shape: ``RecordingStream.log`` costs 50-90 us per call, far too much for a loop that must answer
each vehicle within a sample, while ``send_columns`` costs about 2 us per scalar when many rows go in
one call. So ``submit`` only appends the record to an in-memory deque (lock-free under the GIL, well
under a microsecond, and safe to call from a signal handler's thread), and a background writer thread
turns the pending records into one Arrow batch per vehicle and ships it with ``send_record_batch``
(one call per vehicle and flush; Rerun splits it into per-entity chunks):

* flush policy: while records are pending the writer checks every ``poll_s`` (10 ms) and writes everything
  pending as soon as ``batch_size`` (256) records per vehicle seen are waiting or the oldest one has waited
  ``max_age_s`` (0.5 s), so the file lags the loop by at most ~0.5 s; with nothing pending it sleeps until the
  next record (an idle monitor does not wake it). Per vehicle because each flush costs about
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
    /vehicle/<sysid>/timing/shed           the vehicle's samples shed so far under overload (count)
    /vehicle/<sysid>/alarm                 1.0 while the fault alarm is raised, else 0.0
    /vehicle/<sysid>/run                   0 for the vehicle's first estimator, then 1, 2, ... after restarts
    /vehicle/<sysid>/truth/x/<i>           simulator ground truth (uav/<sysid>/truth), when subscribed
    /vehicle/<sysid>/truth/f/<i>
    /vehicle/<sysid>/truth/d/<i>
    /vehicle/<sysid>/truth/tau             true delay, s (rows only when known)

Timelines: ``sample`` (sequence, k), ``time`` (duration, the sampling instant t in s) and, for the
monitor's own rows, ``wall_time`` (timestamp, receive time). Recording properties (strings) sit under
``/__properties/fault_monitor``; ``layout`` names the version of this table.
``monitor.service.recording_reader`` reads the same paths back; ``RECORDING.md`` beside this file is the
user-facing copy of the table.
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
import weakref
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.service.live_sinks import LiveSink, parse_viewer_url
from monitor.service.records import SampleRecord, TruthRecord
from monitor.service.rrd_stream import LAYOUT_VERSION, StreamWriter, default_blueprint, open_stream, software_versions

__all__ = ["RrdRecorder"]  # the layout and the stream writer are monitor.service.rrd_stream's

log = logging.getLogger(__name__)


class FileSink(StreamWriter):
    """The ``.rrd`` file: lossless (unbounded queue), and a write failure is the run's ``error``."""

    def __init__(
        self,
        path: Path,
        application_id: str,
        recording_id: str,
        properties: dict[str, str],
        recording_name: str,
        **policy: Any,
    ) -> None:
        super().__init__(path.name, **policy)
        self.path = path
        self.error: str | None = None  # the first write failure, as one line (the daemon reports it)
        if self.path.is_dir() or not self.path.parent.is_dir():
            raise UserError(f"cannot write recording {self.path}: not a file in an existing directory")
        try:
            self._rec = open_stream(
                application_id,
                recording_id,
                properties,
                recording_name,
                lambda rec: rec.save(str(self.path), default_blueprint=default_blueprint(())),
            )
        except (OSError, RuntimeError, ValueError) as exc:
            raise UserError(f"cannot write recording {self.path}: {exc}") from exc
        self._thread.start()

    def _after_drain(self, n: int) -> None:
        # Rerun writes the file from its own thread and reports a failure (disk full) only on flush: flush
        # here, in the writer thread, so that a failure is known within one batch, not at close
        if self.error is None and not self._guard(
            f"writing {self.path} (disk full or file removed?)", lambda: self._rec.flush(timeout_sec=5.0)
        ):
            self.stats["failed"] += n

    def _fail_once(self, kind: str, message: str) -> None:
        if self.error is None:
            self.error = f"{kind}: {message}"
        super()._fail_once(kind, message)

    def close(self, timeout_s: float) -> None:
        """Stop the writer, write what is left, the blueprint and the footer (in the calling thread)."""
        self.stop()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        if self._thread.is_alive():
            self._fail_once("close", f"writer thread still busy after {timeout_s} s")
        self._drain()
        self._update_blueprint(force=True)
        # Rerun's flush waits for its file writer, and on a full disk that wait had no end (a CI run hung in
        # close): the footer is written in a helper thread, and close gives up on it after ``timeout_s``
        finisher = threading.Thread(
            target=self._guard,
            args=("close", lambda: self._finish(timeout_s)),
            name=f"close {self.path.name}",
            daemon=True,
        )
        finisher.start()
        finisher.join(timeout_s + 1.0)
        if finisher.is_alive():
            self._fail_once("close", f"the file did not close within {timeout_s:g} s (disk full?)")

    def _finish(self, timeout_s: float) -> None:
        self._rec.flush(timeout_sec=timeout_s)
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

    def __init__(
        self,
        path: str | Path | None,
        application_id: str = "fault-monitor",
        properties: dict[str, str] | None = None,
        *,
        batch_size: int = 256,
        max_age_s: float = 0.5,
        poll_s: float = 0.01,
        recording_name: str | None = None,
        live: Sequence[str] = (),
    ) -> None:
        import uuid

        if live:  # every address checked before the file sink's thread starts
            for url in live:
                parse_viewer_url(url)
        self.path = Path(path) if path is not None else None
        props = {"layout": LAYOUT_VERSION, **software_versions(), **(properties or {})}
        name = recording_name or f"{application_id} {self.path.stem if self.path else 'live'}"
        recording_id = str(uuid.uuid4())
        self._file = (
            None
            if self.path is None
            else FileSink(
                self.path,
                application_id,
                recording_id,
                props,
                name,
                batch_size=batch_size,
                max_age_s=max_age_s,
                poll_s=poll_s,
            )
        )
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
