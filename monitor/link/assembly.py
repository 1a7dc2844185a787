"""Per vehicle: MAVLink messages of one sampling instant -> one sample, whatever order they come in.

Messages may arrive one per datagram, several per datagram, split across reads, in any order, or twice.
Each message's time field names its instant (``time_usec``, or ``time_boot_ms`` modulo 2^32, or a 32-bit
``time_usec`` such as SERVO_OUTPUT_RAW's modulo 2^32 us, unwrapped against the newest instant seen), and every
part is filed under the sample of the vehicle's grid nearest that stamp:

    k = round((t - phase) / h)

The rule for parts stamped a few ms apart (real autopilots stamp each message when they build it; a
DataFlash log stamps each record when it is written): the vehicle's samples sit on a grid ``phase + k h`` of
its own clock, and a part belongs to the grid instant within h/2 of its stamp. The phase is the vehicle's,
not zero: it is set by the vehicle's first timed part (which then sits in the middle of its sample) and
follows the instant messages: each instant message that came a whole number of periods after the previous
one (within h/5) moves it 1/4 of the way to its own offset ``t - k h``. So, at h = 0.02-0.05 s:

* parts stamped within about ``h/2 - J`` of their sample's grid instant join it, J being how far the instant
  messages' own stamps scatter about it; with every message (the instant too) stamped 0-8 ms after the true
  instant, which ``tests/test_link_assembly.py`` flies at random grid phases, every part of every sample joins
  its own sample at h = 0.02, 0.03 and 0.05 s (and at h = 0.02 s with 0-10 ms);
* the phase averages the instants' jitter and follows a vehicle clock whose period differs a little from h
  (tested: 1 % and 2 % slow with 0-8 ms jitter, 1000 samples, none lost; k then counts the vehicle's
  samples); a mismatch of 5 % loses 6-8 % of the samples where the grid slips;
* instant messages faster than h (a 50 Hz stream read at h = 0.05 s) are not on a grid of h and leave the
  phase alone: every h one of them makes the sample, the others are ``duplicates``;
* a vehicle stamping exactly ``k h`` (this project's simulator, the contract) keeps phase 0 and
  ``k = round(time_usec / h)``; a restarted vehicle gets a fresh assembler, hence a fresh phase.

When a sample is processed:
* as soon as the parts the estimator needs are in hand (the instant message and the messages of every
  output; in observe-only mode also the actuator report, which carries u(k); and the signals named in ``needs``,
  which an envelope's scheduler reads to pick its point: a schedule signal that is not an output is needed as
  an output is, timed or a latest value, so that no sample goes to the estimator without it);
* in a monitor-controlled loop the actuator report (the deflection in force, u(k-1) of eqs. 5-6) is
  worth a short wait once the vehicle has been seen to send it: up to ``wait_s`` after the rest is in
  hand, then the sample goes without it (the estimator falls back on the monitor's own last command).
  A vehicle whose reports stop coming is no longer waited for after three such timeouts in a row;
* a message without a time field (VFR_HUD: "it belongs to the instant the vehicle sends it with") cannot be
  filed under an instant: its signals are *latest values*. Each one received replaces the vehicle's previous
  value, stamped with the newest instant heard from the vehicle so far (any timed part; the next one if
  none yet). A sample takes, when it is processed, the newest value received before that moment, if its
  stamp is at most the signal's ``hold`` (default 1 s of the vehicle's clock) older than the sample's
  instant. So it joins the sample still pending when it arrives, and a value that arrives after its sample
  was processed serves the next sample (sample and hold). A sample never waits for a latest value beyond
  the wait it has anyway (for the actuator report); it only cannot be processed while an output it needs
  has no value within its hold (the vehicle's first sample waits for the first value; a stream that stops
  makes its samples ``held_missing``). Autopilots send VFR_HUD at a rate of their own (ArduPilot: a stream
  rate, not per sample), routers split every message into its own datagram, and logs reorder them by a
  few ms: none of that matters to this rule, and ``analyse`` applies it in the log's record order;
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

_GIVE_UP_AFTER = 3  # consecutive waits for an actuator report that expired
_PHASE_GAIN = 0.25  # how far the grid's phase moves towards an instant message's own offset ...
_ON_GRID = 0.2  # ... that came a whole number of periods (within this fraction of h) after the last one


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
    held_missing: int = 0  # samples dropped with every timed part in but a latest value missing or too old

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

    def __init__(
        self,
        signals: SignalMap,
        h: float,
        observe: bool = False,
        wait_s: float = 0.02,
        max_pending: int = 16,
        needs: tuple[str, ...] = (),
    ) -> None:
        """``needs``: measured signals a sample cannot go without besides the outputs (an envelope's schedule)."""
        self.signals = signals
        self.h_us = h * 1e6
        self.observe = observe
        self.wait_s = wait_s
        self.max_pending = max_pending
        self.counters = AssemblyCounters()
        self.actuator_messages = frozenset(signals.actuator_messages())
        self.expect_actuator = observe
        self._timeouts = 0
        # timed message -> (position of its time field, us per unit, wrap in units or 0, its signals)
        self._parts: dict[str, tuple[int, int, int, tuple[tuple[str, int, float, float], ...]]] = {}
        # messages without a time field: message -> ((name, position, scale, offset, hold in us), ...)
        self._held_parts: dict[str, tuple[tuple[str, int, float, float, float], ...]] = {}
        for name, sig in signals.raw.items():  # a derived signal's inputs are joined like any other signal
            if sig.hold is not None:  # not timed: a latest value
                entry = (name, sig.position, sig.scale, sig.offset, sig.hold * 1e6)
                self._held_parts[sig.message] = self._held_parts.get(sig.message, ()) + (entry,)
                continue
            t_pos, unit_us, wrap = _time_field(signals, sig.message)
            prev = self._parts.get(sig.message, (t_pos, unit_us, wrap, ()))
            self._parts[sig.message] = (t_pos, unit_us, wrap, prev[3] + ((name, sig.position, sig.scale, sig.offset),))
        if signals.instant not in self._parts:
            self._parts[signals.instant] = (*_time_field(signals, signals.instant), ())
        extra = [n for n in needs if n not in signals.outputs]
        self.needed_messages = tuple(dict.fromkeys(m for n in extra for m in signals.messages_of(n)))
        wanted = (*signals.messages(observe), *self.needed_messages)
        self.required = frozenset(m for m in wanted if m in self._parts)  # the timed ones
        self._hold_us = {e[0]: e[4] for entries in self._held_parts.values() for e in entries}
        # the latest values the estimator (and the scheduler) need (a derived output: its held inputs)
        self._held_outputs = tuple(n for n in signals.read_from((*signals.outputs, *extra)) if n in self._hold_us)
        self._held: dict[str, tuple[float, int | None]] = {}  # name -> (latest value, its stamp in us)
        self._latest_us: int | None = None  # the newest instant of any timed part accepted
        self._pending: dict[int, _Slot] = {}
        self.last_k: int | None = None
        self._base_us: int | None = None  # the newest instant message's stamp: what wrapping fields unwrap against
        self.phase_us: float | None = None  # the phase of the vehicle's sample grid (None until its first part)
        self._prev_instant_us: int | None = None
        self.seen: set[str] = set()

    def uses(self, message: str) -> bool:
        return message in self._parts or message in self._held_parts

    def _fresh(self, name: str, t_us: int) -> float | None:
        """The latest value of ``name`` if it may serve the sample at ``t_us`` (within its hold), else None."""
        held = self._held.get(name)
        if held is None:
            return None
        value, stamp = held
        return value if stamp is None or t_us - stamp <= self._hold_us[name] else None

    def _complete(self, slot: _Slot) -> bool:
        """Everything the estimator needs: the timed parts, and a latest value within its hold per held output."""
        if slot.time_usec is None or not self.required <= slot.messages:
            return False
        if not self._held_outputs:
            return True
        return all(self._fresh(n, slot.time_usec) is not None for n in self._held_outputs)

    def missing_held(self) -> tuple[str, ...]:
        """Messages of latest-value outputs with no value usable at the newest instant heard (for warnings)."""
        t_us = self._latest_us
        if t_us is None:
            return ()
        names = [n for n in self._held_outputs if self._fresh(n, t_us) is None]
        return tuple(dict.fromkeys(self.signals.raw[n].message for n in names))

    def _add_held(self, message: str, values: tuple, now: float) -> list[AssembledSample]:
        """A message without a time field: its values become the vehicle's latest; a pending sample that only
        lacked them is released: the newest such (older ones not already waiting for their actuator report are
        dropped: answering a burst of old instants helps no one, and a datagram buys one answer anyway)."""
        self._set_held(message, values)
        if not self._held_outputs:
            return []
        ready = [k for k, s in self._pending.items() if s.deadline is None and self._complete(s)]
        if not ready:
            return []
        k = max(ready)
        slot = self._pending[k]
        for kk in [x for x, s in self._pending.items() if x < k and s.deadline is None]:
            self._drop(self._pending.pop(kk))
        if self.expect_actuator and not self.actuator_messages <= slot.messages:
            slot.deadline = now + self.wait_s
            return []
        return self._emit_through(k, now)

    def _set_held(self, message: str, values: tuple) -> None:
        """The message's latest values, stamped with its own time field if it has one (a slower stream given a
        ``hold``), else with the newest instant heard (VFR_HUD)."""
        stamp = self._latest_us
        own = self.signals.time_fields.get(message)
        if own is not None:
            stamp = self._instant_us(int(values[own[0]]), own[1], own[2] if len(own) > 2 else 0)
        for name, pos, scale, offset, _hold in self._held_parts[message]:
            self._held[name] = (scale * values[pos] + offset, stamp)

    def _drop(self, slot: _Slot) -> None:
        c = self.counters
        if slot.time_usec is not None and self.required <= slot.messages:
            c.held_missing += 1  # every timed part was in: what it lacked was a latest value
        else:
            c.incomplete += 1

    def _instant_us(self, stamp: int, unit_us: int, wrap: int) -> int:
        """A stamp in us; a field that wraps (32-bit ms or us) is unwrapped against the newest instant."""
        t = stamp * unit_us
        base = self._base_us
        if not wrap or base is None:
            return t
        span = wrap * unit_us
        diff = (t - base) % span
        if diff >= span // 2:
            diff -= span
        return base + diff

    def _on_grid(self, t_us: int) -> bool:
        """Whether this instant message came a whole number of periods h after the previous one (any, even a
        duplicate): only then may it move the grid's phase (instants faster than h, a log decimated to a longer
        h, would otherwise pull the grid to the first instant of each sample and make k run ahead)."""
        prev, self._prev_instant_us = self._prev_instant_us, t_us
        if prev is None:
            return False
        steps = (t_us - prev) / self.h_us
        return round(steps) >= 1 and abs(steps - round(steps)) <= _ON_GRID

    def _index(self, t_us: int) -> int:
        """The sample of the vehicle's grid nearest ``t_us`` (see the module docstring)."""
        phase = self.phase_us
        return int(round((t_us - phase if phase is not None else t_us) / self.h_us))

    def locate(self, message: str, values: tuple) -> tuple[int, int] | None:
        """``(instant in us, sample index)`` of a timed message of this vehicle (None if the map does not time it)."""
        spec = self._parts.get(message)
        if spec is None:
            return None
        t_us = self._instant_us(int(values[spec[0]]), spec[1], spec[2])
        return t_us, self._index(t_us)

    def index_of(self, message: str, values: tuple) -> int | None:
        """The sample index a message of this vehicle belongs to (None if the map does not use it)."""
        at = self.locate(message, values)
        return at[1] if at is not None else None

    def add(
        self,
        message: str,
        values: tuple,
        route: object,
        now: float,
        max_k: int | None = None,
        k: int | None = None,
        t_us: int | None = None,
    ) -> list[AssembledSample]:
        """File one decoded message (``values``: its unpacked payload) under its instant.

        ``max_k``: the newest instant the vehicle's clock can have reached; parts beyond it are refused
        (``future``), so a forged far-future stamp can neither be processed nor lock later samples out.
        ``k``, ``t_us``: the message's sample index and instant when the caller already computed them (``locate``).
        """
        spec = self._parts.get(message)
        if spec is None:
            if message in self._held_parts:
                self.seen.add(message)
                return self._add_held(message, values, now)
            return []
        if message in self._held_parts:  # a timed message some of whose signals are latest values
            self._set_held(message, values)
        self.seen.add(message)
        t_pos, unit_us, wrap, signals = spec
        if t_us is None:
            t_us = self._instant_us(int(values[t_pos]), unit_us, wrap)
        if k is None:
            k = self._index(t_us)
        c = self.counters
        if max_k is not None and k > max_k:
            c.future += 1
            return []
        instant = message == self.signals.instant
        follow = instant and self._on_grid(t_us)
        if message in self.actuator_messages and not self.expect_actuator:
            self.expect_actuator = True  # it reports its actuator: from now on that report is waited for
        if self.phase_us is None:  # the vehicle's first timed part sits in the middle of its sample
            self.phase_us = t_us - k * self.h_us
        if self.last_k is not None:
            if k <= self.last_k:
                if not instant:
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
                self._drop(self._pending.pop(oldest))
            slot = self._pending[k] = _Slot()
        elif message in slot.messages:
            c.duplicate_parts += 1
            return []
        slot.messages.add(message)
        for name, pos, scale, offset in signals:
            slot.values[name] = scale * values[pos] + offset
        if instant:
            slot.time_usec = t_us
            slot.route = route
            if self._base_us is None or t_us > self._base_us:
                self._base_us = t_us
            if follow:  # the grid's phase follows the instants (module docstring)
                self.phase_us += (t_us - k * self.h_us - self.phase_us) * _PHASE_GAIN
        if self._latest_us is None or t_us > self._latest_us:
            if self._latest_us is None and self._held:  # latest values heard before any timed part: stamp them now
                self._held = {n: (v, t_us if st is None else st) for n, (v, st) in self._held.items()}
            self._latest_us = t_us
        if not self._complete(slot):
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
        held = self._held
        for kk in sorted(x for x in self._pending if x <= k):
            slot = self._pending.pop(kk)
            time_usec = slot.time_usec
            if time_usec is None or not self._complete(slot):
                self._drop(slot)
                continue
            values = slot.values
            if held:
                for name in held:
                    value = self._fresh(name, time_usec)
                    if value is not None:
                        values[name] = value
            if self.signals.derived:
                self.signals.complete_derived(values)
            out.append(AssembledSample(kk, time_usec, values, slot.route, now))
        if out:
            self.counters.samples += len(out)
        self.last_k = k if self.last_k is None else max(self.last_k, k)
        return out


def _time_field(signals: SignalMap, message: str) -> tuple[int, int, int]:
    """(position, us per unit, wrap in units or 0) of a timed message's time field."""
    spec = signals.time_fields[message]
    return (spec[0], spec[1], spec[2] if len(spec) > 2 else 0)
