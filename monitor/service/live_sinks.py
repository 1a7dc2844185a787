"""Live Rerun viewers as recorder sinks (``run --rerun-url URL``, ``--rerun-spawn``), never slowing the loop.

Each viewer is one ``LiveSink``: its own ``RecordingStream``, its own bounded queue and its own thread,
so a viewer that is slow, stopped or gone costs only its own oldest records (counted in
``stats["dropped"]``), never the loop's time nor the file's rows (``RrdRecorder`` keeps the file on a
stream, queue and thread of its own).

Why the sink probes the viewer's TCP port itself (every ``PROBE_S``) instead of trusting Rerun: in
rerun-sdk 0.41 ``connect_grpc`` to an address where nothing listens blocks 5 s, ``disconnect`` then
waits 5 s more, and once a connected viewer is killed every later ``send``/``flush`` still succeeds
while the data goes nowhere. So a sink connects only to a port that accepts connections, drops the
connection when the port stops answering, and connects again (same recording id, so the viewer shows
one recording) when it is back. Until then the queue keeps the newest ``LIVE_QUEUE_MAX`` records, which
the viewer gets on (re)connection. One WARNING line per episode (nothing answers, went away, falls
behind), one INFO line when streaming (again), one summary line at close.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.parse
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.service.rrd_stream import StreamWriter, default_blueprint, open_stream

__all__ = [
    "LIVE_QUEUE_MAX",
    "SPAWN_PORT",
    "LiveSink",
    "find_viewer",
    "parse_viewer_url",
    "spawn_viewer",
    "viewer_answers",
]

log = logging.getLogger(__name__)

LIVE_QUEUE_MAX = 5000  # records kept for a viewer that is behind or away: ~100 s of one vehicle at 50 Hz
PROBE_S = 2.0  # how often a sink checks that its viewer still answers (and retries one that does not)
PROBE_TIMEOUT_S = 0.5
FLUSH_TIMEOUT_S = 0.5  # per batch: a viewer that takes longer is behind, and its queue says so
LIVE_MAX_AGE_S = 0.1  # a viewer is for watching: ship batches 5x sooner than the file does
SPAWN_PORT = 9876  # the Rerun viewer's own default port
SPAWN_WAIT_S = 10.0  # how long a spawned viewer may take to listen
SPAWN_GRACE_S = 0.5  # ... and then to fail to open its window


def parse_viewer_url(url: str) -> tuple[str, int]:
    """``(host, port)`` of a viewer's gRPC address ``rerun+http(s)://HOST:PORT/proxy``, else a ``UserError``.

    Checked before anything starts so a typo is one line and exit 2, not a sink that never connects.
    """
    hint = "give the address the viewer prints, e.g. rerun+http://127.0.0.1:9876/proxy"
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in ("rerun+http", "rerun+https"):
        raise UserError(f"--rerun-url {url!r}: not a rerun+http:// or rerun+https:// address; {hint}")
    try:
        port = parts.port
    except ValueError:
        port = None
    if not parts.hostname or port is None or parts.path.rstrip("/") != "/proxy" or parts.query or parts.fragment:
        raise UserError(f"--rerun-url {url!r}: expected HOST:PORT and the path /proxy; {hint}")
    return parts.hostname, port


def find_viewer(search_path: str | None = None) -> str:
    """The ``rerun`` executable: on ``search_path`` (default: PATH, then beside this Python), else a ``UserError``.

    Beside ``sys.executable`` because ``pip install rerun-sdk`` puts it in the environment's ``bin``,
    which is not on PATH when the monitor is started by its full path without activating the venv.
    """
    if search_path is not None:
        found = shutil.which("rerun", path=search_path)
    else:
        found = shutil.which("rerun") or shutil.which("rerun", path=str(Path(sys.executable).parent))
    if found is None:
        raise UserError(
            "--rerun-spawn: no 'rerun' viewer executable found on PATH (pip install rerun-sdk "
            "provides it); or start a viewer yourself and give --rerun-url"
        )
    return found


def viewer_answers(host: str, port: int, timeout_s: float = PROBE_TIMEOUT_S) -> bool:
    """True when something accepts TCP connections at ``host:port`` (a bare connect: the viewer logs nothing)."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def spawn_viewer(executable: str, port: int = SPAWN_PORT) -> str:
    """Start a local viewer on loopback ``port`` (unless one answers there already); returns its gRPC URL.

    Detached (its own session, output discarded) so that it outlives the monitor and a Ctrl-C in the
    monitor's terminal does not close it; a viewer that fails to start (no display) shows up as the
    sink's "nothing answers" WARNING.
    """
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    if viewer_answers("127.0.0.1", port):
        log.info("a viewer already listens at %s: streaming to it instead of spawning another", url)
        return url
    try:
        proc = subprocess.Popen(
            [executable, "--bind", "127.0.0.1", "--port", str(port), "--expect-data-soon"],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            env={**os.environ, "RERUN_APP_ONLY": "true"},
        )
    except OSError as exc:
        raise UserError(f"--rerun-spawn: cannot start {executable}: {exc.strerror or exc}") from None
    # wait (bounded) until it listens, so the sink's first probe finds it and a viewer that cannot start
    # (no display) is one error line now rather than a WARNING later
    # (it listens before it opens its window: one that has no display goes away just after)
    deadline = time.monotonic() + SPAWN_WAIT_S
    while not viewer_answers("127.0.0.1", port, 0.1) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    try:
        code = proc.wait(SPAWN_GRACE_S)
    except subprocess.TimeoutExpired:
        code = None
    if code is not None:
        raise UserError(
            f"--rerun-spawn: the viewer {executable} exited with code {code} at once (no display? "
            "run `rerun` to see why, or start a viewer elsewhere and give --rerun-url)"
        )
    log.info("spawned a Rerun viewer (%s, pid %d) at %s", executable, proc.pid, url)
    return url


class LiveSink(StreamWriter):
    """One live viewer: connect when it answers, drop the oldest records when it is behind or away."""

    def __init__(
        self,
        url: str,
        application_id: str,
        recording_id: str,
        properties: dict[str, str],
        recording_name: str,
        *,
        maxlen: int = LIVE_QUEUE_MAX,
        probe_s: float = PROBE_S,
        max_age_s: float = LIVE_MAX_AGE_S,
        **policy: Any,
    ) -> None:
        super().__init__(url, maxlen=maxlen, max_age_s=max_age_s, **policy)
        self.url = url
        self.host, self.port = parse_viewer_url(url)
        self.probe_s = probe_s
        self._open = (application_id, recording_id, properties, recording_name)
        self._fault: str | None = None  # the first failure since the last batch: the connection is dropped
        self._warned = False  # one WARNING per episode; reset when streaming (again)
        self._dropped_seen = 0
        self.connections = 0
        self._thread.start()

    @property
    def connected(self) -> bool:
        return self._rec is not None

    def close(self) -> None:
        """Ask the thread to send what is left and disconnect; ``join`` waits for it (bounded)."""
        self.stop()

    def join(self, timeout_s: float) -> None:
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.warning(
                "live viewer %s: still sending after %.1f s at close; left behind (the file is complete)",
                self.url,
                timeout_s,
            )

    # -- the sink's thread ----------------------------------------------------------------------------

    def _run(self) -> None:
        next_probe = 0.0
        timeout = 0.0
        while not self._sleep(timeout):
            now = time.monotonic()
            if now >= next_probe:
                next_probe = now + self.probe_s
                self._probe()
            if self._rec is not None and self._due():
                self._drain()
            # records to send: check every poll_s; else sleep until one comes or the next probe is due
            busy = self._rec is not None and self._pending
            timeout = self.poll_s if busy else max(0.0, next_probe - time.monotonic())
        self._finish()

    def _probe(self) -> None:
        answers = viewer_answers(self.host, self.port)
        if self._rec is None:
            if answers:
                self._connect()
            else:
                self._warn(f"nothing answers at {self.url}; retrying every {self.probe_s:g} s")
            return
        if not answers:
            self._lose("went away")
            return
        dropped = self.stats["dropped"]
        if dropped > self._dropped_seen:
            self._warn(f"live viewer {self.url} falls behind: {dropped} samples dropped for it so far")
        elif self._warned:
            log.info("live viewer %s caught up (%d samples dropped for it)", self.url, dropped)
            self._warned = False
        self._dropped_seen = dropped

    def _connect(self) -> None:
        def attach(rec: Any) -> None:
            rec.connect_grpc(self.url, default_blueprint=default_blueprint(self._sysids))

        try:
            self._rec = open_stream(*self._open, attach)
        except Exception as exc:  # noqa: BLE001 - a viewer must never take the loop down
            self._warn(f"cannot stream to {self.url}: {type(exc).__name__}: {exc}")
            return
        self._blueprint_ids = frozenset()  # the new connection has no layout yet: send it with the next batch
        self.connections += 1
        self._dropped_seen = self.stats["dropped"]
        self._warned = False
        log.info(
            "streaming to the live viewer at %s%s",
            self.url,
            f" (again; {self._dropped_seen} samples dropped for it so far)" if self.connections > 1 else "",
        )

    def _lose(self, reason: str) -> None:
        rec, self._rec = self._rec, None
        self._warn(
            f"live viewer {self.url} {reason}; its newest {self._pending.maxlen} samples are kept until it "
            "answers again (the recording file is not affected)"
        )
        if rec is not None:
            try:
                rec.disconnect()
            except Exception as exc:  # noqa: BLE001 - the connection is gone either way
                log.debug("live viewer %s: disconnect: %s", self.url, exc)

    def _warn(self, message: str) -> None:
        if not self._warned:
            self._warned = True
            log.warning("%s", message)

    def _write_vehicle(self, *args: Any) -> None:
        if self._rec is None:
            raise ConnectionError("not connected")
        super()._write_vehicle(*args)

    def _fail_once(self, kind: str, message: str) -> None:
        self._fault = self._fault or f"{kind} failed ({message})"

    def _after_drain(self, n: int) -> None:
        if self._fault is None and self._rec is not None:
            self._guard("flush", lambda: self._rec.flush(timeout_sec=FLUSH_TIMEOUT_S))
        if self._fault is not None:
            fault, self._fault = self._fault, None
            self._lose(f"cannot be sent to: {fault}")

    def _finish(self) -> None:
        if self._rec is not None:
            self._drain()
            self._update_blueprint(force=True)
        if self._rec is not None:
            rec, self._rec = self._rec, None
            try:
                rec.flush(timeout_sec=2.0)
                rec.disconnect()
            except Exception as exc:  # noqa: BLE001
                log.warning("live viewer %s: the last samples may be missing (%s)", self.url, exc)
        log.info(
            "live viewer %s: %d records sent, %d dropped, %d unsent",
            self.url,
            self.stats["written"],
            self.stats["dropped"],
            len(self._pending),
        )
