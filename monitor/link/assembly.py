"""Per vehicle: MAVLink messages of one sampling instant -> one sample, whatever order they come in.

Messages may arrive one per datagram, several per datagram, split across reads, in any order, or twice.
Each message's time field names its instant (``time_usec``, or ``time_boot_ms`` modulo 2^32, unwrapped
against the newest instant seen), so every part is filed under its sample index ``k = round(t / h)``.

When a sample is processed:
* as soon as the parts the estimator needs are in hand (the instant message and the messages of every
  output; in observe-only mode also the actuator report, which carries u(k));
* in a monitor-controlled loop the actuator report (the deflection in force, u(k-1) of eqs. 5-6) is
  worth a short wait once the vehicle has been seen to send it: up to ``wait_s`` after the rest is in
  hand, then the sample goes without it (the estimator falls back on the monitor's own last command).
  A vehicle whose reports stop coming is no longer waited for after three such timeouts in a row;
* a sample still incomplete when a newer one is processed is dropped (counted ``incomplete``); parts
  for an instant already processed or dropped are counted: the instant message itself as ``duplicates``
  (same k) or ``stale`` (older k), any other part as ``late_parts``; a part repeated while its sample
  is pending as ``duplicate_parts``.

Nothing here knows sockets or clocks: ``now`` comes from the caller (monotonic time live, the log's own
time in ``analyse``), which is what lets ``run`` and ``analyse`` share this code.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from monitor.link.signals import SignalMap

__all__ = ["AssembledSample", "AssemblyCounters", "SampleAssembler"]

_MS_WRAP = 1 << 32
_GIVE_UP_AFTER = 3  # consecutive waits for an actuator report that expired


class AssembledSample:
    """One vehicle's signals at one sampling instant, in plant units (``scale`` and ``offset`` applied)."""

    __slots__ = ("k", "time_usec", "values", "route", "ready_at")

    def __init__(self, k: int, time_usec: int, values: dict[str, float], route: object, ready_at: float) -> None:
        self.k = k
        self.time_usec = time_usec
        self.values = values
        self.route = route  # where the instant message came from (replies go there)
        self.ready_at = ready_at


@dataclass
class AssemblyCounters:
    samples: int = 0
    duplicates: int = 0  # the instant message of a sample already processed, again
    stale: int = 0  # the instant message of a sample older than the last one processed
    incomplete: int = 0  # instants dropped before the estimator's parts were all in hand
    late_parts: int = 0  # parts for an instant already processed or dropped
    duplicate_parts: int = 0  # a message repeated for an instant still pending
    waited_out: int = 0  # samples processed without the actuator report they waited for
    future: int = 0  # parts too far ahead of the vehicle's last instant to be believed

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class _Slot:
    __slots__ = ("values", "messages", "time_usec", "route", "deadline")

    def __init__(self) -> None:
        self.values: dict[str, float] = {}
        self.messages: set[str] = set()
        self.time_usec: int | None = None
        self.route: object = None
        self.deadline: float | None = None


class SampleAssembler:
    """The parts of one vehicle's samples; ``add`` and ``poll`` return the samples ready, oldest first."""

    def __init__(self, signals: SignalMap, h: float, observe: bool = False, wait_s: float = 0.02,
                 max_pending: int = 16) -> None:
        self.signals = signals
        self.h_us = h * 1e6
        self.observe = observe
        self.wait_s = wait_s
        self.max_pending = max_pending
        self.counters = AssemblyCounters()
        self.required = frozenset(signals.messages(observe))
        self.actuator_messages = frozenset(signals.actuator_messages())
        self.expect_actuator = observe
        self._timeouts = 0
        self._parts: dict[str, tuple[int, int, tuple[tuple[str, int, float, float], ...]]] = {}
        for name, sig in signals.measured.items():
            t_pos, unit_us = signals.time_fields[sig.message]
            prev = self._parts.get(sig.message, (t_pos, unit_us, ()))
            self._parts[sig.message] = (t_pos, unit_us, prev[2] + ((name, sig.position, sig.scale, sig.offset),))
        if signals.instant not in self._parts:
            self._parts[signals.instant] = (*signals.time_fields[signals.instant], ())
        self._pending: dict[int, _Slot] = {}
        self.last_k: int | None = None
        self._latest_ms: int | None = None
        self.seen: set[str] = set()

    def uses(self, message: str) -> bool:
        return message in self._parts

    def _instant_us(self, stamp: int, unit_us: int) -> int:
        if unit_us == 1:
            return stamp
        if self._latest_ms is None:
            return stamp * unit_us
        base = self._latest_ms
        diff = (stamp - base) % _MS_WRAP
        if diff >= _MS_WRAP // 2:
            diff -= _MS_WRAP
        return (base + diff) * unit_us

    def index_of(self, message: str, values: tuple) -> int | None:
        """The sample index a message of this vehicle belongs to (None if the map does not use it)."""
        spec = self._parts.get(message)
        if spec is None:
            return None
        return int(round(self._instant_us(int(values[spec[0]]), spec[1]) / self.h_us))

    def add(self, message: str, values: tuple, route: object, now: float,
            max_k: int | None = None, k: int | None = None) -> list[AssembledSample]:
        """File one decoded message (``values``: its unpacked payload) under its instant.

        ``max_k``: the newest instant the vehicle's clock can have reached; parts beyond it are refused
        (``future``), so a forged far-future stamp can neither be processed nor lock later samples out.
        ``k``: the message's sample index when the caller already computed it (``index_of``).
        """
        spec = self._parts.get(message)
        if spec is None:
            return []
        self.seen.add(message)
        t_pos, unit_us, signals = spec
        t_us = self._instant_us(int(values[t_pos]), unit_us)
        if k is None:
            k = int(round(t_us / self.h_us))
        c = self.counters
        if max_k is not None and k > max_k:
            c.future += 1
            return []
        if message in self.actuator_messages and not self.expect_actuator:
            self.expect_actuator = True  # it reports its actuator: from now on that report is waited for
        if self.last_k is not None:
            if k <= self.last_k:
                if message != self.signals.instant:
                    c.late_parts += 1
                elif k == self.last_k:
                    c.duplicates += 1
                else:
                    c.stale += 1
                return []
        slot = self._pending.get(k)
        if slot is None:
            if len(self._pending) >= self.max_pending:
                oldest = min(self._pending)
                if k < oldest:
                    c.incomplete += 1
                    return []
                del self._pending[oldest]
                c.incomplete += 1
            slot = self._pending[k] = _Slot()
        elif message in slot.messages:
            c.duplicate_parts += 1
            return []
        slot.messages.add(message)
        for name, pos, scale, offset in signals:
            slot.values[name] = scale * values[pos] + offset
        if message == self.signals.instant:
            slot.time_usec = t_us
            slot.route = route
            self._latest_ms = t_us // 1000
        if not self.required <= slot.messages:
            return []
        if self.expect_actuator and not self.actuator_messages <= slot.messages:
            if slot.deadline is None:
                slot.deadline = now + self.wait_s
            return []
        if slot.deadline is not None or self.actuator_messages <= slot.messages:
            self._timeouts = 0
        return self._emit_through(k, now)

    def poll(self, now: float) -> list[AssembledSample]:
        """Samples whose wait for the actuator report has run out."""
        due = [k for k, s in self._pending.items() if s.deadline is not None and s.deadline <= now]
        if not due:
            return []
        self.counters.waited_out += len(due)
        self._timeouts += len(due)
        if self._timeouts >= _GIVE_UP_AFTER and not self.observe:
            self.expect_actuator = False
        return self._emit_through(max(due), now)

    def flush(self, now: float) -> list[AssembledSample]:
        """Everything that can still be processed (end of a log): waiting samples go without their report."""
        ready = [k for k, s in self._pending.items() if s.deadline is not None]
        return self._emit_through(max(ready), now) if ready else []

    def pending_instants(self) -> int:
        return len(self._pending)

    def _emit_through(self, k: int, now: float) -> list[AssembledSample]:
        """Process every waiting sample up to ``k`` in order; incomplete older ones are dropped."""
        out: list[AssembledSample] = []
        for kk in sorted(x for x in self._pending if x <= k):
            slot = self._pending.pop(kk)
            if slot.time_usec is None or not self.required <= slot.messages:
                self.counters.incomplete += 1
                continue
            out.append(AssembledSample(kk, slot.time_usec, slot.values, slot.route, now))
        if out:
            self.counters.samples += len(out)
        self.last_k = k if self.last_k is None else max(self.last_k, k)
        return out
