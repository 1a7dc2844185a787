"""Zenoh side of the monitor: estimates, alarm events, the status queryable and the liveliness token.

Why a queue and a thread: the control loop must never wait for Zenoh. The loop only appends a tuple of
references (no JSON, no copies) to a deque whose length it checks against ``queue_max``; a publisher
thread wakes every ``poll_s`` (2 ms), turns what is pending into JSON and puts it with
``CongestionControl.BLOCK`` (so Zenoh itself does not drop in bursts). Why polling instead of a
blocking queue: waking the thread on every sample made it fight the loop for the GIL on each sample
(measured: +30 us per sample, benchmarks/bench_monitor.py); a 2 ms poll costs at most 2 ms of latency. If
subscribers or the network fall behind, the thread blocks, the queue fills, and the loop drops *new estimates*
(counted in ``dropped`` and logged at most every 5 s) instead of blocking. Alarm events are never dropped: they are
rare, bounded by the hysteresis, and the one thing a listener must not miss. The status queryable always answers the
newest estimate, dropped from the stream or not, because the loop stores it before the hand-off.
"""

from __future__ import annotations

import collections
import json
import logging
import math
import threading
import time
from typing import Any

import zenoh

__all__ = ["EstimatePublisher", "estimate_payload", "alarm_payload"]

log = logging.getLogger(__name__)

_JSON = zenoh.Encoding.APPLICATION_JSON

# (sysid, k, t, f_hat, x_hat, residual, u, tau, alarm, command_applied, commands_effective, envelope): built in
# the loop from references, no conversions; envelope is (point name, inside) for an envelope model, else None
EstimateItem = tuple


def _finite(values) -> list[float | None]:
    """Strict JSON has no NaN or Infinity: a non-finite number is sent as null."""
    return [v if math.isfinite(v) else None for v in map(float, values)]


def estimate_payload(item: EstimateItem, unit: str) -> dict[str, Any]:
    """The contract's ``fault/estimate`` payload (plant units; ``tau`` = observed delay in seconds or null).

    Beyond the contract: ``command_applied`` (did the previous command act, per the vehicle's actuator
    report; null when it cannot be told) and ``commands_effective`` (false while most recent ones did not); for
    an envelope model only, ``point`` (the name of the point that estimated the sample) and ``in_envelope``
    (false while the schedule's values are outside the identified range: the alarm is paused).
    """
    sysid, k, t, f_hat, x_hat, residual, u, tau, alarm, applied, effective = item[:11]
    envelope = item[11] if len(item) > 11 else None
    payload = {
        "sysid": sysid,
        "k": k,
        "t": t,
        "f_hat": _finite(f_hat),
        "x_hat": _finite(x_hat),
        "residual": _finite(residual),
        "u": _finite(u),
        "tau": tau,
        "alarm": alarm,
        "unit": unit,
        "command_applied": applied,
        "commands_effective": effective,
    }
    if envelope is not None:
        payload["point"], payload["in_envelope"] = envelope
    return payload


def alarm_payload(sysid: int, k: int, t: float, state: str, f_hat) -> dict[str, Any]:
    """The contract's ``fault/alarm`` payload; ``state`` is "raised" or "cleared"."""
    return {"sysid": sysid, "k": k, "t": t, "state": state, "f_hat": _finite(f_hat)}


class EstimatePublisher:
    """Owns the monitor's Zenoh entities (not the session) and the publisher thread."""

    def __init__(
        self,
        session: zenoh.Session,
        prefix: str,
        name: str,
        unit: str = "deg",
        queue_max: int = 10_000,
        poll_s: float = 0.002,
    ) -> None:
        self.session = session
        self.prefix = prefix.rstrip("/")
        self.unit = unit
        self.queue_max = queue_max
        self.dropped = 0
        self.published = 0
        self.latest: dict[int, EstimateItem] = {}
        self.status_extra: dict[str, Any] = {}  # the daemon's health (e.g. a recording error), added to status replies
        self.poll_s = poll_s
        self._queue: collections.deque = collections.deque()
        self._stop = threading.Event()
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._last_drop_log = 0.0
        self.token = session.liveliness().declare_token(f"{self.prefix}/monitor/{name}")
        self.queryable = session.declare_queryable(f"{self.prefix}/*/fault/status", self._on_query)
        self._thread = threading.Thread(target=self._run, name="zenoh-publisher", daemon=True)
        self._thread.start()

    # --- called by the loop (hot path) -------------------------------------------------------------
    def estimate(self, item: EstimateItem) -> None:
        self.latest[item[0]] = item
        if len(self._queue) >= self.queue_max:
            self.dropped += 1
            now = time.monotonic()
            if now - self._last_drop_log > 5.0:
                self._last_drop_log = now
                log.warning(
                    "Zenoh publisher behind: %d estimates dropped so far (queue of %d full)",
                    self.dropped,
                    self.queue_max,
                )
            return
        self._queue.append(item)

    def alarm(self, sysid: int, k: int, t: float, state: str, f_hat) -> None:
        self._queue.append(("alarm", alarm_payload(sysid, k, t, state, f_hat)))

    # --- publisher thread ----------------------------------------------------------------------------
    def _publisher(self, key: str) -> zenoh.Publisher:
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.session.declare_publisher(
                key, encoding=_JSON, congestion_control=zenoh.CongestionControl.BLOCK
            )
        return pub

    def _run(self) -> None:
        while True:
            stopping = self._stop.wait(self.poll_s)
            while self._queue:
                self._send(self._queue.popleft())
            if stopping:
                return

    def _send(self, item: tuple) -> None:
        try:
            if item[0] == "alarm":
                payload = item[1]
                key = f"{self.prefix}/{payload['sysid']}/fault/alarm"
            else:
                payload = estimate_payload(item, self.unit)
                key = f"{self.prefix}/{item[0]}/fault/estimate"
            self._publisher(key).put(json.dumps(payload, allow_nan=False))
            self.published += 1
        except Exception as exc:  # a closed session or a bad value costs a log line, not the thread
            log.debug("publish failed: %s", exc)

    def _on_query(self, query: zenoh.Query) -> None:
        """Answer with each matching vehicle's latest estimate, on that vehicle's concrete key."""
        try:
            wanted = query.key_expr
            for sysid, item in list(self.latest.items()):
                key = f"{self.prefix}/{sysid}/fault/status"
                if wanted.intersects(zenoh.KeyExpr(key)):
                    payload = {**estimate_payload(item, self.unit), **self.status_extra}
                    query.reply(key, json.dumps(payload, allow_nan=False), encoding=_JSON)
        except Exception as exc:
            log.debug("status query failed: %s", exc)

    def close(self, timeout: float = 2.0) -> list[Any]:
        """Drain what is queued (bounded by ``timeout``), stop the thread; return entities to undeclare."""
        self._stop.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.warning("Zenoh publisher still busy after %.1f s; %d items not sent", timeout, len(self._queue))
        return [self.queryable, *self._publishers.values(), self.token]
