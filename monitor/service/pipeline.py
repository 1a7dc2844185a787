"""From frames to answers: the one path ``fault-monitor run`` and ``fault-monitor analyse`` share.

``on_frames(route, frames, t0)`` is called by a link (or the tlog reader) with the frames of one read:
each frame the signal maps use is unpacked and filed with its vehicle's assembler
(``VehicleTable.message``); each completed sample steps the estimator (``VehicleTable.process``) and
then, in this order: the command goes back on the route the sample came from (not in observe-only
mode), the ground-station feedback (``FHAT`` every sample, ``STATUSTEXT`` on alarm events) follows it,
the estimate is handed to the Zenoh thread and the record to the recorder. Nothing on this path waits
for I/O other than a non-blocking send. Processing time is measured from the moment the bytes were read
to the end of the hand-offs.

``analyse`` passes ``route=None`` (nothing to answer) and the log's own times as ``now``/``wall``.

Operating point (a plant identified about a trim): the estimator's quantities are deviations from it; what
leaves on MAVLink and in the Zenoh estimate's ``u`` is the absolute deflection ``u0 + u``; the recording
keeps the measured values as measured (absolute) and the estimator's y, x_hat, f_hat, u, residual as
deviations (its properties carry the operating point).

An envelope model: each sample's deviations are from the operating point of the point that stepped it; the
Zenoh estimate says which (``point``, ``in_envelope``) and so does the recording (``envelope/point``, the point's
index, and ``envelope/inside``); the summary counts ``outside_envelope``. A single-point model's estimate,
recording and summary are what they were.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, fields
from typing import Any

from monitor.link.dialect import MessageLayout, layout_by_name, mavlink
from monitor.link.frames import FrameCounters, RawFrame
from monitor.link.outgoing import alarm_text_frame, command_frame, fhat_frames
from monitor.link.transports import Read
from monitor.service.group import GroupView
from monitor.service.records import SampleRecord
from monitor.service.vehicles import Processed, Vehicle, VehicleTable, answer_within

__all__ = ["Pipeline", "MessageCounters", "percentile"]

log = logging.getLogger("monitor.run")

_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
MAX_FRAMES_PER_DATAGRAM = 32  # a 64 KB datagram can pack ~800 frames: the rest is counted, not processed
ROUND_S = 0.004  # answering budget of one round: the links are drained again after it (newer samples supersede)


def _headers(data: bytes) -> Iterator[tuple[int, int]]:
    """``(msgid, sysid)`` of each MAVLink frame in a datagram, from the headers alone (at most the per-datagram cap)."""
    i, n = 0, len(data)
    for _ in range(MAX_FRAMES_PER_DATAGRAM):
        if i + 6 > n:
            return
        stx = data[i]
        if stx == 0xFD and i + 10 <= n:
            yield data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16, data[i + 5]
            i += 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
        elif stx == 0xFE:
            yield data[i + 5], data[i + 3]
            i += 8 + data[i + 1]
        else:
            return


def _priority(entry: tuple[Vehicle, Any, int]) -> tuple[int, int]:
    """Who is answered first in a round: the vehicle shed most in a row, then the oldest sample (bounded runs)."""
    return -entry[0].shed_run, entry[2]


def percentile(values, p: float) -> float | None:
    data = sorted(values)
    if not data:
        return None
    return data[min(len(data) - 1, int(round(p / 100 * (len(data) - 1))))]


@dataclass
class MessageCounters:
    heartbeats: int = 0
    foreign: int = 0  # valid messages no signal map uses (routers forward plenty of them)
    excess: int = 0  # frames beyond the per-datagram cap, and samples beyond one per vehicle per datagram
    old_datagrams: int = 0  # datagrams past every deadline when read (the monitor could not run): not parsed

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Pipeline:
    """Frames -> vehicle table -> estimator -> command, feedback, Zenoh, recorder."""

    def __init__(
        self,
        table: VehicleTable,
        *,
        send_commands: bool = True,
        gcs_feedback: bool = True,
        publisher=None,
        recorder=None,
    ) -> None:
        self.table = table
        self.send_commands = send_commands and (table.compensate or not table.observe)
        self.gcs_feedback = gcs_feedback
        self.publisher = publisher
        self.recorder = recorder
        self.frames = FrameCounters()
        self.messages = MessageCounters()
        self.processing_s: deque[float] = deque(maxlen=100_000)
        self.commands_sent = 0
        self.feedback_sent = 0
        # a monitor group (``run --group``): asked per processed sample whether this member answers it; None: alone
        self.group: GroupView | None = None
        self.served = 0  # samples this member answered (a group member: the rest it only kept warm)
        self.kept_warm = 0
        self.warned_v1 = False
        self.round_ns = int(ROUND_S * 1e9)
        self.overloaded = False  # in an overload episode (shedding; one WARNING at its start)
        self._newest: dict[int, tuple[Vehicle, Any, int]] = {}  # per vehicle: its newest sample not yet answered
        self._shed_round: dict[int, int] = {}  # samples shed since the last round ended, per vehicle
        self._shed_checked = 0
        self._flush = getattr(publisher, "flush", None)  # once per round: the Zenoh puts of the round
        self._wanted: dict[int, tuple[str, MessageLayout]] = {}
        self.scheduled = any(m.envelope is not None for m in table.fleet.models())
        for model in table.fleet.models():
            for name in {model.signals.instant, *(s.message for s in model.signals.raw.values())}:
                layout = layout_by_name(name)
                if layout is not None:  # a DataFlash map names the log's messages (fed by on_message)
                    self._wanted[layout.msgid] = (layout.name, layout)

    # --- hot path ------------------------------------------------------------------------------------
    def on_frames(
        self,
        route: tuple | None,
        frames: list[RawFrame],
        t0_ns: int,
        now: float | None = None,
        wall: float | None = None,
    ) -> None:
        """Frames of one read, every sample they complete processed in order (``analyse``: a log is never late)."""
        if now is None:
            now = time.monotonic()
        if wall is None:
            wall = time.time()
        for vehicle, sample in self._samples(route, frames, now):
            self._handle(vehicle, sample, now, wall, t0_ns)
        if self._flush is not None:
            self._flush()

    def on_reads(self, reads: list[Read]) -> None:
        """The live path: every read one wake-up of the loop drained. Each vehicle's newest complete sample is
        kept (the older ones are shed) and the kept ones are answered within the round's budget (``answer``)."""
        now = time.monotonic()
        newest = self._newest
        # observe-only (nothing is sent): a sample that a newer one overtook is still estimated, in order, while it
        # is within its deadline; there is no answer to keep current, and each one shed is a sample the observer
        # loses (a vehicle streaming faster than real time, a replay through a router, sends bursts of its own)
        estimate_all = self.table.observe and not self.table.compensate
        for route, frames, t0_ns in reads:
            for vehicle, sample in self._samples(route, frames, now):
                older = newest.get(vehicle.sysid)
                if older is not None:
                    if estimate_all:
                        self._settle(older, time.perf_counter_ns(), now, time.time())
                    else:
                        self._shed(older[0])
                newest[vehicle.sysid] = (vehicle, sample, t0_ns)
        self.answer()

    def answer(self) -> bool:
        """Answer the kept samples, the vehicles shed most in a row first (then the oldest sample first), until
        the round's budget is spent; a sample older than its vehicle's deadline is shed instead. Returns whether
        samples are left for the next round (the daemon calls again at once, after the links were drained)."""
        newest = self._newest
        if newest:
            clock = time.perf_counter_ns
            start = clock()
            stop_at = start + self.round_ns
            now, wall = time.monotonic(), time.time()
            entries = sorted(newest.values(), key=_priority) if len(newest) > 1 else list(newest.values())
            for entry in entries:
                t = clock()
                if t >= stop_at:
                    break
                del newest[entry[0].sysid]
                self._settle(entry, t, now, wall + (t - start) * 1e-9)
        if self._shed_round:
            self._warn_shed()
        if self._flush is not None:
            self._flush()
        return bool(newest)

    def _settle(self, entry: tuple[Vehicle, Any, int], t_ns: int, now: float, wall: float) -> None:
        """One kept sample at clock ``t_ns`` (``wall``: the wall time then): answered, or shed when it is past its
        vehicle's deadline; dropped when its vehicle was restarted or expired since (its old estimator is gone)."""
        vehicle, sample, t0_ns = entry
        if self.table.vehicles.get(vehicle.sysid) is not vehicle:
            return
        if t_ns - t0_ns > vehicle.deadline_ns:
            self._shed(vehicle)
            return
        vehicle.shed_run = 0
        # the receive time is the arrival's (what the observed delay and the recording's wall_time mean), not this
        # round's: a sample kept from an earlier round waited in the monitor, not on the link
        self._handle(vehicle, sample, now, wall - (t_ns - t0_ns) * 1e-9, t0_ns)

    def on_stale(self, datagrams: list[bytes]) -> None:
        """Datagrams a link read too late to be worth parsing (``UdpLink.stale_ns``): each instant message among
        them is a shed sample of its vehicle. Read from the frame headers alone (no CRC check: a forged header
        can only add to a count)."""
        self.messages.old_datagrams += len(datagrams)
        vehicles, wanted = self.table.vehicles, self._wanted
        for data in datagrams:
            for msgid, sysid in _headers(data):
                vehicle = vehicles.get(sysid)
                entry = wanted.get(msgid)
                if vehicle is not None and entry is not None and entry[0] == vehicle.model.signals.instant:
                    self._shed(vehicle)
        if self._shed_round:
            self._warn_shed()

    @property
    def deadline_s(self) -> float:
        """The longest any vehicle's sample may wait for its answer: older datagrams need not be parsed."""
        return max((answer_within(m) for m in self.table.fleet.models()), default=0.0)

    def pending(self) -> bool:
        """Whether kept samples wait for the next round."""
        return bool(self._newest)

    def _shed(self, vehicle: Vehicle) -> None:
        """A sample not answered because a newer one of its vehicle came, or it grew too old: a lost sample."""
        vehicle.shed += 1
        vehicle.shed_run += 1
        self.table.counters.shed += 1
        self._shed_round[vehicle.sysid] = self._shed_round.get(vehicle.sysid, 0) + 1

    def _warn_shed(self) -> None:
        """One WARNING when shedding starts (an overload episode), naming who lost what in that round."""
        shed, self._shed_round = self._shed_round, {}
        if self.overloaded:
            return
        self.overloaded = True
        self._shed_checked = self.table.counters.shed
        who = ", ".join(f"vehicle {sysid}: {n}" for sysid, n in sorted(shed.items())[:5])
        more = f" and {len(shed) - 5} more vehicles" if len(shed) > 5 else ""
        log.warning(
            "overloaded: %d sample(s) shed (%s%s); each vehicle's newest sample is answered, older ones are shed "
            "(lost samples to the estimator, counted per vehicle as 'shed')",
            sum(shed.values()),
            who,
            more,
        )

    def check_overload(self) -> bool:
        """Housekeeping (1 Hz): the overload episode ends with a check that found no new shed sample (INFO)."""
        total = self.table.counters.shed
        if self.overloaded and total == self._shed_checked:
            self.overloaded = False
            log.info("no longer overloaded: %d sample(s) shed so far", total)
            return True
        self._shed_checked = total
        return False

    def _samples(self, route: tuple | None, frames: list[RawFrame], now: float) -> Iterator[tuple[Vehicle, Any]]:
        """The samples the frames of one read complete. On a datagram link at most one sample per vehicle per
        datagram and at most ``MAX_FRAMES_PER_DATAGRAM`` frames are looked at: one packet must not buy many
        answers."""
        datagram = route is not None and getattr(route[0], "datagram", False)
        if datagram and len(frames) > MAX_FRAMES_PER_DATAGRAM:
            self.messages.excess += len(frames) - MAX_FRAMES_PER_DATAGRAM
            frames = frames[:MAX_FRAMES_PER_DATAGRAM]
        answered: set[int] | None = set() if datagram else None
        wanted, message = self._wanted, self.table.message
        for msgid, sysid, _compid, payload in frames:
            entry = wanted.get(msgid)
            if entry is None:
                if msgid == _HEARTBEAT:
                    self.messages.heartbeats += 1
                else:
                    self.messages.foreign += 1
                continue
            completed = message(sysid, entry[0], entry[1].decode(payload), route, now)
            for vehicle, sample in completed:
                if answered is not None:
                    if sysid in answered:
                        self.messages.excess += 1
                        continue
                    answered.add(sysid)
                yield vehicle, sample

    def on_message(self, sysid: int, name: str, values: tuple, now: float, wall: float) -> None:
        """One message already decoded by name (a DataFlash log's record: ``values`` in its FMT column order),
        filed like a frame's payload; nothing to answer (route None)."""
        for vehicle, sample in self.table.message(sysid, name, values, None, now):
            self._handle(vehicle, sample, now, wall, time.perf_counter_ns())

    def poll(self, now: float | None = None, wall: float | None = None) -> None:
        """Process samples whose wait for an actuator report ran out (called every few ms by the daemon)."""
        now = time.monotonic() if now is None else now
        for vehicle, sample in self.table.poll(now):
            self._handle(vehicle, sample, now, time.time() if wall is None else wall, time.perf_counter_ns())
        if self._flush is not None:
            self._flush()

    def flush(self, now: float, wall: float) -> None:
        """End of input (a log): process every sample still waiting for its actuator report."""
        for vehicle, sample in self.table.flush(now):
            self._handle(vehicle, sample, now, wall, time.perf_counter_ns())

    def _handle(self, vehicle: Vehicle, sample, now: float, wall: float, t0_ns: int) -> None:
        p = self.table.process(vehicle, sample, wall, now)
        if p is None:
            return
        r = p.result
        route = sample.route
        # a group member steps every vehicle's estimator (above) and answers only the vehicles it owns: a warm
        # member's outputs are gated here and nowhere else
        group = self.group
        if group is not None:
            group.stepped(vehicle.sysid, r.k, vehicle.state)  # compared with the owner's step in its beats
        serving = group is None or group.serves(vehicle.sysid, now)
        if not serving:
            self.kept_warm += 1
            if self.publisher is not None:
                self.publisher.latest.pop(vehicle.sysid, None)  # its status is the owner's to answer
            route = None
        elif self.group is not None:
            self.served += 1
        if route is not None:
            # the command first, the ground-station feedback after it, in ONE write: a syscall saved per
            # sample, and MAVLink peers read several frames per datagram as they do on a stream
            link, peer = route
            enc = link.encoder_for(peer)  # MAVLink 1 for a peer that speaks only v1
            out = b""
            if self.send_commands:
                # the absolute deflection u0 + u(k) (the estimator's u is a deviation from the operating point);
                # --compensate: the compensation alone, an increment the vehicle adds to its autopilot's deflection
                sent = p.compensation if p.compensation is not None else p.u_abs
                out = command_frame(enc, vehicle.model.signals.command, vehicle.sysid, sample.time_usec, sent)
                self.commands_sent += 1
            if self.gcs_feedback:
                out += fhat_frames(enc, sample.time_usec, r.f_hat_values)
                if p.alarm_event is not None:
                    out += alarm_text_frame(enc, vehicle.sysid, p.alarm_event, p.f_mag, vehicle.model.plant.unit)
                self.feedback_sent += 1
            if out:
                link.send(out, peer)
        raised = vehicle.alarm.raised
        if self.publisher is not None and serving:
            env = vehicle.model.envelope
            self.publisher.estimate(
                (
                    vehicle.sysid,
                    r.k,
                    p.t,
                    r.f_hat_values,
                    r.x_hat_values,
                    r.residual_values,
                    p.u_abs,
                    p.tau_obs,
                    raised,
                    p.command_applied,
                    vehicle.commands_effective,
                    (env.names[p.point], p.inside) if env is not None and p.point is not None else None,
                )
            )
            if p.alarm_event is not None:
                self.publisher.alarm(vehicle.sysid, r.k, p.t, p.alarm_event, r.f_hat_values)
        if p.alarm_event is not None:
            log.info(
                "vehicle %d: alarm %s at k=%d (|f_hat| = %.3g %s)",
                vehicle.sysid,
                p.alarm_event,
                r.k,
                p.f_mag,
                vehicle.model.plant.unit,
            )
        processing = (time.perf_counter_ns() - t0_ns) * 1e-9
        self.processing_s.append(processing)
        if self.recorder is not None:
            self.recorder.submit(self._record(p, wall, processing, None if self.group is None else serving))

    @staticmethod
    def _record(p: Processed, wall: float, processing: float, served: bool | None = None) -> SampleRecord:
        r, values = p.result, p.sample.values
        sig = p.vehicle.model.signals
        elevator = values.get(sig.actuator[0]) if sig.actuator else None
        return SampleRecord(
            sysid=p.vehicle.sysid,
            k=r.k,
            t=p.t,
            wall=wall,
            y=p.y,
            alpha=values.get("alpha"),
            q=values.get("q"),
            elevator=elevator,
            x_hat=r.x_hat_values,
            f_hat=r.f_hat_values,
            u=r.u_values,
            residual=r.residual_values,
            tau_obs=p.tau_obs,
            processing_s=processing,
            alarm=p.vehicle.alarm.raised,
            run=p.vehicle.run,
            point=p.point,
            inside=p.inside,
            shed=p.vehicle.shed,
            served=served,
        )

    # --- housekeeping and reporting -----------------------------------------------------------------
    def warn_frames(self) -> bool:
        """One WARNING, the first time a signed link refuses MAVLink 1 frames (they can never be signed, so
        the vehicle's samples are lost for a setting, not for an attack); the exit summary counts them."""
        if self.warned_v1 or not self.frames.v1_refused:
            return False
        self.warned_v1 = True
        log.warning(
            "MAVLink 1 frames refused (%d so far): the links are signed (--signing-key) and MAVLink 1 cannot "
            "be signed; set the sender to MAVLink 2 (ArduPilot: SERIALn_PROTOCOL = 2)",
            self.frames.v1_refused,
        )
        return True

    def counts(self) -> dict[str, int]:
        out = {
            **self.frames.as_dict(),
            **self.messages.as_dict(),
            **self.table.assembly_totals(),
            **self.table.counters.as_dict(),
            "commands": self.commands_sent,
            "feedback": self.feedback_sent,
        }
        if self.group is not None:
            group = self.group
            out.update(served=self.served, kept_warm=self.kept_warm, stalls=group.stalls, out_of_step=group.out_of_step)
        if self.publisher is not None:
            out.update(published=self.publisher.published, publish_drops=self.publisher.dropped)
        if not self.scheduled:  # only an envelope has an identified range to be outside of
            del out["outside_envelope"]
        return out

    def summary(self) -> str:
        c = self.counts()
        p50, p99 = percentile(self.processing_s, 50), percentile(self.processing_s, 99)
        timing = (
            f"processing p50 {p50 * 1e6:.0f} us, p99 {p99 * 1e6:.0f} us"
            if p50 is not None and p99 is not None
            else "no processing times"
        )
        order = (
            "processed",
            "duplicates",
            "stale",
            "incomplete",
            "held_missing",
            "late_parts",
            "waited_out",
            "no_report",
            "not_applied",
            "rejected_values",
            "outside_envelope",
            "future",
            "foreign_source",
            "excess",
            "shed",
            "old_datagrams",
            "frames_v1",
            "garbage",
            "truncated",
            "bad_signature",
            "v1_refused",
            "wrong_dialect",
            "foreign",
            "refused",
            "skipped",
            "vehicles_seen",
            "restarts",
            "resets",
            "commands",
            "feedback",
            "served",
            "kept_warm",
            "stalls",
            "out_of_step",
            "published",
            "publish_drops",
        )
        names = {
            "processed": "samples processed",
            "vehicles_seen": "vehicles",
            "old_datagrams": "old datagrams (not parsed)",
            "frames_v1": "MAVLink 1 frames",
            "v1_refused": "MAVLink 1 refused (signed link)",
        }
        parts = [f"{names.get(key, key.replace('_', ' '))} {c[key]}" for key in order if key in c]
        return ", ".join(parts) + f"; {timing}" + self._shed_by_vehicle()

    def _shed_by_vehicle(self, most: int = 10) -> str:
        """``; shed per vehicle: 1: 12, 7: 3`` (the ``most`` vehicles that lost most; nothing when none did)."""
        shed = self.table.shed_by_vehicle()
        if not shed:
            return ""
        worst = sorted(shed.items(), key=lambda item: (-item[1], item[0]))
        text = ", ".join(f"{sysid}: {n}" for sysid, n in worst[:most])
        return f"; shed per vehicle: {text}" + (f" and {len(worst) - most} more vehicles" if len(worst) > most else "")
