"""Zenoh side of the monitor: estimates, alarm events, the status queryable and the liveliness token.

Why the loop formats and a thread puts: a publisher thread that turned each estimate into JSON competed with the
loop for the GIL, and every syscall of the loop (a read, a send) then could wait for the thread's switch interval
before it went on (the loop's sends were its most expensive line under load: ``benchmarks/bench_monitor.py
--overload``). Now ``estimate`` only keeps the item (a tuple of references: no JSON, no copies); ``flush``, which
the pipeline calls once per round after every command of the round has gone out, formats the round's estimates
(``estimate_json``: a few us, a third of ``json.dumps``), queues them and wakes the thread once. The thread only
puts (Zenoh's own work, in Rust) with ``CongestionControl.BLOCK``, so Zenoh does not drop in bursts; it sleeps on
an event between rounds (no polling: an idle monitor does not wake it).

If subscribers or the network fall behind, the thread blocks, the queue fills, and the loop drops *new estimates*
(counted in ``dropped`` and logged at most every 5 s) instead of blocking. Alarm events are never dropped: they are
rare, bounded by the hysteresis, and the one thing a listener must not miss. The status queryable always answers the
newest estimate, dropped from the stream or not, because ``estimate`` stores it first.
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

__all__ = ["EstimatePublisher", "estimate_payload", "estimate_json", "alarm_payload"]

log = logging.getLogger(__name__)

_JSON = zenoh.Encoding.APPLICATION_JSON

# (sysid, k, t, f_hat, x_hat, residual, u, tau, alarm, command_applied, commands_effective, envelope): built in
# the loop from references, no conversions; envelope is (point name, inside) for an envelope model, else None
EstimateItem = tuple


def _finite(values) -> list[float | None]:
    """Strict JSON has no NaN or Infinity: a non-finite number is sent as null."""
    return [v if math.isfinite(v) else None for v in map(float, values)]


def estimate_payload(item: EstimateItem, unit: str, member: str | None = None) -> dict[str, Any]:
    """The contract's ``fault/estimate`` payload (plant units; ``tau`` = observed delay in seconds or null).

    Beyond the contract: ``command_applied`` (did the previous command act, per the vehicle's actuator
    report; null when it cannot be told) and ``commands_effective`` (false while most recent ones did not); for
    an envelope model only, ``point`` (the name of the point that estimated the sample) and ``in_envelope``
    (false while the schedule's values are outside the identified range: the alarm is paused); for a member of a
    monitor group only (``run --group``), ``member`` (the name of the member that answered the sample).
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
    if member is not None:
        payload["member"] = member
    return payload


def _json_numbers(values) -> str:
    """``[0.1, null]``: floats as ``json.dumps`` writes them (``repr``), a non-finite one as null."""
    if type(values) is list:  # the loop's: floats (or ints from a limit written as an integer)
        floats = [float(v) for v in values]
    else:
        floats = values.tolist() if hasattr(values, "tolist") else [float(v) for v in values]
    text = repr(floats)  # one C call for the common case; "nan", "inf" are the only reprs with an "n"
    if "n" not in text:
        return text
    return "[" + ", ".join(repr(v) if v - v == 0.0 else "null" for v in map(float, floats)) + "]"


_JSON_LITERAL = {True: "true", False: "false", None: "null"}


def estimate_json(item: EstimateItem, unit: str, member: str | None = None) -> str:
    """``json.dumps(estimate_payload(item, unit, member))``, the same keys in the same order, at a third of the cost
    (the loop formats one per answered sample; tested equal, NaN and infinities included)."""
    sysid, k, t, f_hat, x_hat, residual, u, tau, alarm, applied, effective = item[:11]
    envelope = item[11] if len(item) > 11 else None
    tail = (
        f',"point":{_json_string(envelope[0])},"in_envelope":{_JSON_LITERAL[bool(envelope[1])]}'
        if envelope is not None
        else ""
    )
    tail += f',"member":{_json_string(member)}}}' if member is not None else "}"
    return (
        f'{{"sysid":{int(sysid)},"k":{int(k)},"t":{_json_float(t)},"f_hat":{_json_numbers(f_hat)},'
        f'"x_hat":{_json_numbers(x_hat)},"residual":{_json_numbers(residual)},"u":{_json_numbers(u)},'
        f'"tau":{"null" if tau is None else _json_float(tau)},"alarm":{_JSON_LITERAL[bool(alarm)]},'
        f'"unit":{_json_string(unit)},"command_applied":{_JSON_LITERAL[applied if applied is None else bool(applied)]},'
        f'"commands_effective":{_JSON_LITERAL[bool(effective)]}' + tail
    )


_JSON_STRINGS: dict[str, str] = {}


def _json_string(text: str) -> str:
    """``json.dumps(text)``, remembered: the unit and the member's name are the same in every estimate."""
    out = _JSON_STRINGS.get(text)
    if out is None:
        out = _JSON_STRINGS[text] = json.dumps(text)
    return out


def _json_float(value: float) -> str:
    value = float(value)
    if value - value != 0.0:  # NaN or infinite: strict JSON has neither (estimate_payload's t and tau pass as-is)
        raise ValueError(f"Out of range float values are not JSON compliant: {value!r}")
    return repr(value)


def alarm_payload(sysid: int, k: int, t: float, state: str, f_hat) -> dict[str, Any]:
    """The contract's ``fault/alarm`` payload; ``state`` is "raised" or "cleared"."""
    return {"sysid": sysid, "k": k, "t": t, "state": state, "f_hat": _finite(f_hat)}


class EstimatePublisher:
    """Owns the monitor's Zenoh entities (not the session) and the thread that puts."""

    def __init__(
        self,
        session: zenoh.Session,
        prefix: str,
        name: str,
        unit: str = "deg",
        queue_max: int = 10_000,
        member: str | None = None,
    ) -> None:
        self.session = session
        self.member = member  # a monitor group's member: named in every payload (the member that answered)
        self.prefix = prefix.rstrip("/")
        self.unit = unit
        self.queue_max = queue_max
        self.dropped = 0
        self.published = 0
        self.latest: dict[int, EstimateItem] = {}
        self.status_extra: dict[str, Any] = {}  # the daemon's health (e.g. a recording error), added to status replies
        self._round: list[EstimateItem] = []  # the estimates of the round in progress
        self._queue: collections.deque[tuple[str, str]] = collections.deque()  # (key, JSON) for the thread
        self._wake = threading.Event()
        self._stop = False
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._last_drop_log = 0.0
        self.token = session.liveliness().declare_token(f"{self.prefix}/monitor/{name}")
        self.queryable = session.declare_queryable(f"{self.prefix}/*/fault/status", self._on_query)
        self._thread = threading.Thread(target=self._run, name="zenoh-publisher", daemon=True)
        self._thread.start()

    # --- called by the loop (hot path) -------------------------------------------------------------
    def estimate(self, item: EstimateItem) -> None:
        self.latest[item[0]] = item
        self._round.append(item)

    def flush(self) -> None:
        """Format the round's estimates and hand them to the thread (once per round, after the round's commands)."""
        if not self._round:
            return
        items, self._round = self._round, []
        queue, unit, prefix, member = self._queue, self.unit, self.prefix, self.member
        for item in items:
            if len(queue) >= self.queue_max:
                self._drop()
                continue
            try:
                queue.append((f"{prefix}/{item[0]}/fault/estimate", estimate_json(item, unit, member)))
            except ValueError as exc:  # a non-finite time: not JSON; costs this estimate, not the loop
                log.debug("estimate not published: %s", exc)
        self._wake.set()

    def _drop(self) -> None:
        self.dropped += 1
        now = time.monotonic()
        if now - self._last_drop_log > 5.0:
            self._last_drop_log = now
            log.warning(
                "Zenoh publisher behind: %d estimates dropped so far (queue of %d full)", self.dropped, self.queue_max
            )

    def alarm(self, sysid: int, k: int, t: float, state: str, f_hat) -> None:
        payload = json.dumps(alarm_payload(sysid, k, t, state, f_hat), allow_nan=False)
        self._queue.append((f"{self.prefix}/{sysid}/fault/alarm", payload))  # never dropped
        self._wake.set()

    # --- publisher thread ----------------------------------------------------------------------------
    def _publisher(self, key: str) -> zenoh.Publisher:
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.session.declare_publisher(
                key, encoding=_JSON, congestion_control=zenoh.CongestionControl.BLOCK
            )
        return pub

    def _run(self) -> None:
        queue = self._queue
        while True:
            self._wake.wait()
            self._wake.clear()
            while queue:
                key, payload = queue.popleft()
                try:
                    self._publisher(key).put(payload)
                    self.published += 1
                except Exception as exc:  # a closed session costs a log line, not the thread
                    log.debug("publish failed: %s", exc)
            if self._stop:
                return

    def _on_query(self, query: zenoh.Query) -> None:
        """Answer with each matching vehicle's latest estimate, on that vehicle's concrete key."""
        try:
            wanted = query.key_expr
            for sysid, item in list(self.latest.items()):
                key = f"{self.prefix}/{sysid}/fault/status"
                if wanted.intersects(zenoh.KeyExpr(key)):
                    payload = {**estimate_payload(item, self.unit, self.member), **self.status_extra}
                    query.reply(key, json.dumps(payload, allow_nan=False), encoding=_JSON)
        except Exception as exc:
            log.debug("status query failed: %s", exc)

    def close(self, timeout: float = 2.0) -> list[Any]:
        """Put what is queued (bounded by ``timeout``), stop the thread; return entities to undeclare."""
        self.flush()
        self._stop = True
        self._wake.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.warning("Zenoh publisher still busy after %.1f s; %d items not sent", timeout, len(self._queue))
        return [self.queryable, *self._publishers.values(), self.token]
