"""The per-vehicle table: each vehicle's loop, for the system ids the fleet has a model for.

A vehicle appears with its first message (its estimator state starts at zero) and is forgotten after
``timeout`` seconds of silence. Its model comes from the ``Fleet`` (``monitor.service.fleet_file``: the
fleet config, TOML, one ``[vehicle.<sysid>]`` table each with ``plant``, ``gains`` and optionally
``signals``, or else the default ``--plant``/``--gains``); a system id with neither is refused with one
log line (and counted).

Messages go to the vehicle's ``SampleAssembler`` (monitor/link/assembly.py), which hands back whole
samples in order; duplicates and stale samples are counted there. Why a "restart" rule: a vehicle
process restarted under the same sysid comes from a new source and starts again at a low k, which would
otherwise look stale until the timeout. A new route may take over once the old one has been silent for
``restart_silence`` seconds (or its TCP connection closed); from that takeover until the new route's
first sample, any message with a time field (of any message the signal map uses, not only the instant)
whose k is below the old run's last k, or beyond where its clock can be, is a restart: a fresh estimator
and a new ``run`` in the recording. Why until the first sample and not only on the first message: a
restarted vehicle often speaks first with a HEARTBEAT, which has no time to judge; the takeover is
remembered and the first timed message decides. A replayed old message from another address while the
vehicle is live does not qualify and is still refused (``foreign_source``).

Why a vehicle that never assembles a sample gets a WARNING: the most common set-up mistake is a signal
map that names a message the vehicle does not send; a silent monitor would look like a network fault.

An envelope model (``VehicleModel.envelope``) is scheduled per vehicle and per sample on the values of the
schedule's signals in the assembled sample (the assembler needs them as it needs the outputs):
``monitor.model.scheduling`` picks the point (the nearest, with a dead band of 10 % of the spacing about each
midpoint) and interpolates the points' trims at the sample; the estimator's state (and the last command, in
deviations too) is re-based to that trim every sample, and the point's own estimator and signal map step the
sample about it. A sample whose
schedule values lie outside the identified range (further below the lowest point or above the highest than
half the spacing to its neighbour, or not finite) is *outside*: the estimator still steps it on the nearest
point, so f_hat goes on, but the alarm does not see it (nothing is raised or cleared on it), it is counted in
``outside_envelope`` (a sample the monitor could not judge), and one WARNING per episode says why; an INFO
line says when the vehicle is back inside.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from monitor.link.assembly import AssembledSample, AssemblyCounters, SampleAssembler
from monitor.model.estimator import EstimatorState, StepResult
from monitor.model.flight_condition import needed_signals, schedule_value
from monitor.model.known_inputs import lag_factor
from monitor.model.scheduling import choose_point, hull_gap, outside_variables, rebase, trim_weights
from monitor.service.alarm import Alarm, AlarmConfig
from monitor.service.delay import DelayTracker
from monitor.service.fleet_file import EnvelopeModel, Fleet, VehicleModel

__all__ = ["Vehicle", "Processed", "TableCounters", "VehicleTable", "answer_within"]

log = logging.getLogger(__name__)

MISSING_WARNING_S = 3.0  # a vehicle heard for this long without one sample gets a WARNING (checked at 1 Hz)
APPLIED_WINDOW = 10  # commands judged applied or not, per vehicle
NOT_APPLIED_ENTER = 5  # this many of the window not applied: the monitor says its commands do not act
APPLIED_TOLERANCE = 1e-3  # relative: float32 on the wire twice (command, report) is ~1e-7
MAX_SPEEDUP = 100.0  # a vehicle's clock runs at most this much faster than ours (simulators with --speedup)
CLOCK_JUMP_S = 2.0  # far-future stamps from the bound source alone for this long: its clock really jumped
FUTURE_SLACK = 10  # samples a vehicle's clock may be ahead beyond that (jitter, lost samples)
ANSWER_WITHIN = 0.8  # of a sample period: an older sample is shed, not answered (its command would come late)


def answer_within(model: VehicleModel) -> float:
    """Seconds a sample may wait for its answer: ``ANSWER_WITHIN`` of a sample period (a lagged plant's commands
    may be in flight up to its ``tau_max``)."""
    plant = model.plant
    return ANSWER_WITHIN * (plant.tau_max if plant.lags is not None else plant.h)


def _compensation_in_force(vehicle: Vehicle, values: dict[str, float], c_sent: list[float]) -> list[float] | None:
    """``--compensate``: the compensation in force as the vehicle reports it (the signal ``compensation``,
    ``ACTUATOR_OUTPUT_STATUS.actuator[2]`` from sim-vehicle), or None while it is not known to report it.

    A vehicle is taken to report it once a reported value equals, to float32, a non-zero compensation the monitor
    sent: a vehicle that leaves the field at zero (it does not report it) never does, and the estimator then
    assumes each compensation acted, as before."""
    value = values.get("compensation")
    if value is None or not math.isfinite(value) or len(c_sent) != 1:
        return None
    if not vehicle.reports_compensation:
        if c_sent[0] != 0.0 and abs(value - c_sent[0]) <= 1e-6 * max(1.0, abs(c_sent[0])):
            vehicle.reports_compensation = True
        else:
            return None
    return [float(value)]


def _lagged_inputs(
    vehicle: Vehicle, lag: dict[str, float], values: dict[str, float], k: int, h: float
) -> dict[str, float]:
    """``values`` with each lagged known input replaced by its first-order lag (``[known_inputs.lag]``), stepped
    over the samples since the last one (a lost sample is a longer step); restarted at the first sample, after a
    vehicle restart (``k`` going back) and where a value was missing."""
    before: dict[str, float] = {}
    steps = 0
    if vehicle.input_lagged is not None and k > vehicle.input_lagged[0]:
        steps, before = k - vehicle.input_lagged[0], vehicle.input_lagged[1]
    state: dict[str, float] = {}
    out = dict(values)
    for name, seconds in lag.items():
        value = values.get(name, math.nan)
        if not math.isfinite(value):
            continue
        last = before.get(name)
        state[name] = value if last is None else last + lag_factor(seconds, steps * h) * (value - last)
        out[name] = state[name]
    vehicle.input_lagged = (k, state)
    return out


class Vehicle:
    """One vehicle's loop: assembler, estimator state, alarm, observed delay, where to answer."""

    __slots__ = (
        "sysid",
        "model",
        "state",
        "alarm",
        "delay",
        "assembler",
        "route",
        "last_seen",
        "first_seen",
        "processed",
        "skipped",
        "warned_missing",
        "last_command",
        "last_compensation",
        "reports_compensation",
        "last_command_k",
        "no_report",
        "rejected",
        "last_reject_log",
        "applied",
        "commands_effective",
        "not_applied",
        "last_sample_at",
        "run",
        "future_since",
        "taken_over",
        "held_missing_seen",
        "held_missing_log",
        "point",
        "outside",
        "outside_samples",
        "outside_episode",
        "switches",
        "trim",
        "input_trim",
        "input_columns",
        "input_lagged",
        "shed",
        "shed_run",
        "deadline_ns",
    )

    def __init__(
        self,
        sysid: int,
        model: VehicleModel,
        alarm: AlarmConfig,
        route: object,
        now: float,
        observe: bool,
        wait_s: float,
        run: int = 0,
    ) -> None:
        self.sysid = sysid
        self.run = run  # how many estimators this sysid had before this one (restarts, expiries)
        self.model = model
        self.state: EstimatorState = model.estimator.initial_state()
        self.alarm = Alarm(alarm)
        self.delay = DelayTracker()
        needs = needed_signals(model.envelope.envelope.schedule) if model.envelope is not None else ()
        known = model.plant.known_inputs
        if known is not None:  # the known inputs' signals (roll, r) are needed as the outputs are
            needs = (*needs, *known.signals)
        self.assembler = SampleAssembler(model.signals, model.plant.h, observe=observe, wait_s=wait_s, needs=needs)
        self.route = route
        self.last_seen = self.first_seen = now
        self.processed = self.skipped = self.no_report = self.rejected = self.not_applied = 0
        self.warned_missing = False
        self.last_command: list[float] | None = None
        self.last_compensation: list[float] | None = None  # --compensate: c(k-1), the last compensation sent
        self.reports_compensation = False  # ... and whether the vehicle reports the one in force (it matched one)
        self.last_command_k: int | None = None
        self.last_reject_log = -1e9
        self.applied: deque[bool] = deque(maxlen=APPLIED_WINDOW)  # were the last commands seen to act?
        self.commands_effective = True
        self.last_sample_at: float | None = None
        self.future_since: float | None = None
        self.taken_over = False  # a new route took over after silence and has not given a sample yet
        self.held_missing_seen = 0  # the assembler's held_missing count when last warned about (or resolved)
        self.held_missing_log = -1e9
        self.point: int | None = None  # an envelope model: the point the last sample used (None before the first)
        self.outside = False  # ... whether that sample was outside the identified envelope
        self.outside_samples = 0  # samples outside the envelope, in all and in the current episode
        self.outside_episode = 0
        self.switches = 0  # point switches
        # an envelope model: (state offset, y0, u0) of the trim interpolated at the last sample, the deviations'
        # origin (None before the first sample)
        self.trim: tuple[np.ndarray, tuple[float, ...], tuple[float, ...]] | None = None
        self.input_trim: dict[str, float] | None = None  # ... and the linear known inputs' trims
        self.input_columns: dict[str, np.ndarray] | None = None  # ... and their columns, interpolated too
        # the lagged known inputs ([known_inputs.lag]): {signal: value} and the sample they were last stepped at
        self.input_lagged: tuple[int, dict[str, float]] | None = None
        self.shed = 0  # samples not answered under overload (a newer one came first, or it grew too old)
        self.shed_run = 0  # ... since its last answered sample
        # how old a sample may be when its answer goes out: within its sample period (the contract's "late" is
        # not applied by (k+1) h), with room for the way back; a lagged plant's commands may be in flight longer
        self.deadline_ns = int(answer_within(model) * 1e9)


@dataclass
class TableCounters:
    processed: int = 0
    skipped: int = 0  # samples never received, predicted over by the estimator
    refused: int = 0  # samples (instant messages) from system ids with no model
    vehicles_seen: int = 0
    vehicles_expired: int = 0
    restarts: int = 0
    no_report: int = 0  # samples without an actuator report: u(k-1) = the monitor's own last command
    resets: int = 0  # estimator states that became non-finite and were reset
    rejected_values: int = 0  # samples whose estimator inputs were non-finite or outside their range
    foreign_source: int = 0  # messages claiming a vehicle's sysid from another link/peer while it is live
    not_applied: int = 0  # commands the next sample's actuator report shows did not act
    outside_envelope: int = 0  # samples outside an envelope's identified range: estimated, not judged by the alarm
    shed: int = 0  # samples not answered under overload: lost samples to the estimator (monitor.service.pipeline)

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Processed:
    """The outcome of one processed sample, for the reply, the publishers and the recorder."""

    __slots__ = (
        "vehicle",
        "sample",
        "result",
        "t",
        "y",
        "tau_obs",
        "alarm_event",
        "f_mag",
        "command_applied",
        "u_abs",
        "compensation",
        "point",
        "inside",
    )

    def __init__(
        self,
        vehicle: Vehicle,
        sample: AssembledSample,
        result: StepResult,
        t: float,
        y: list[float],
        tau_obs: float | None,
        alarm_event: str | None,
        f_mag: float,
        command_applied: bool | None = None,
        u_abs: list[float] | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.sample = sample
        self.result = result
        self.t = t
        self.y = y
        self.tau_obs = tau_obs
        self.alarm_event = alarm_event
        self.f_mag = f_mag
        self.command_applied = command_applied  # did the previous command act (None: cannot tell)?
        # the absolute deflection u0 + u(k): what goes on the wire (observe-only: what the vehicle reported)
        self.u_abs = u_abs if u_abs is not None else list(result.u_values)
        self.compensation: list[float] | None = None  # --compensate: what is sent (G f_hat), added on board
        self.point: int | None = None  # an envelope model: the index of the point that stepped the sample
        self.inside: bool | None = None  # ... and whether its schedule values were inside the identified range


class VehicleTable:
    """Routes messages to each vehicle's assembler and samples to its estimator; creates and drops vehicles."""

    def __init__(
        self,
        fleet: Fleet,
        alarm: AlarmConfig,
        timeout: float = 10.0,
        restart_silence: float = 1.0,
        observe: bool = False,
        wait_s: float = 0.02,
        compensate: bool = False,
    ) -> None:
        """``observe``: the vehicle's own controller flies, nothing is sent. ``compensate``: it flies too, and
        each sample is answered with the fault compensation ``K3 f_hat`` alone, which the vehicle adds to its
        controller's deflection; the estimator runs as observe-only (it needs the reported deflection)."""
        self.fleet = fleet
        self.alarm = alarm
        self.timeout = timeout
        self.restart_silence = min(restart_silence, timeout)
        self.compensate = compensate
        self.observe = observe or compensate
        self.wait_s = wait_s
        self.vehicles: dict[int, Vehicle] = {}
        self.counters = TableCounters()
        self._refused_logged: set[int] = set()
        self._instants = {m.signals.instant for m in fleet.models()}
        self._retired: list[Vehicle] = []
        self._runs: dict[int, int] = {}  # assembly counts of restarted and expired vehicles, for the summary

    def _create(self, sysid: int, name: str, route: object, now: float) -> Vehicle | None:
        model = self.fleet.model_for(sysid)
        if model is None:
            if name in self._instants:  # counted once per sample, not once per message
                self.counters.refused += 1
            if sysid not in self._refused_logged:
                self._refused_logged.add(sysid)
                log.warning(
                    "refusing vehicle sysid %d from %s: no plant/gains for it (fleet file or --plant/--gains)",
                    sysid,
                    _where(route),
                )
            return None
        run = self._runs.get(sysid, -1) + 1
        self._runs[sysid] = run
        vehicle = self.vehicles[sysid] = Vehicle(sysid, model, self.alarm, route, now, self.observe, self.wait_s, run)
        self.counters.vehicles_seen += 1
        op = model.signals.describe_operating_point() if model.envelope is None else model.envelope.describe()
        log.info(
            "vehicle sysid %d from %s: new estimator (plant %s; %s%s)",
            sysid,
            _where(route),
            model.name,
            model.signals.describe(),
            f"; {op}" if op else "",
        )
        return vehicle

    def message(
        self, sysid: int, name: str, values: tuple, route: object, now: float
    ) -> list[tuple[Vehicle, AssembledSample]]:
        """File one decoded message; returns the samples it completed (oldest first).

        Who may speak for a vehicle: the link and peer it is bound to. While that source is live
        (heard within ``restart_silence``), the same sysid from anywhere else is refused and counted; after
        that silence, or at once when the bound TCP connection closed, a new source takes over. Until the new
        source's first sample, a timed message whose k goes backwards (or beyond where the clock can be) is
        a restart (fresh estimator, next run), whichever message it is and whatever came before it.
        """
        vehicle = self.vehicles.get(sysid)
        if vehicle is None:
            vehicle = self._create(sysid, name, route, now)
            if vehicle is None:
                return []
        asm = vehicle.assembler
        at = asm.locate(name, values)
        k = at[1] if at is not None else None
        instant = name == asm.signals.instant
        last_k = asm.last_k
        # where the vehicle's clock can be: only worth working out for a stamp beyond the usual slack
        max_k = (
            self._max_k(vehicle, now) if last_k is not None and k is not None and k > last_k + FUTURE_SLACK else None
        )
        new_route = route != vehicle.route
        if new_route and now - vehicle.last_seen < self.restart_silence and _alive(vehicle.route):
            self.counters.foreign_source += 1
            return []
        if (
            (new_route or vehicle.taken_over)
            and k is not None
            and last_k is not None
            and (k < last_k or (max_k is not None and k > max_k))
        ):
            return self._restart(vehicle, name, values, route, now, "new source", k)
        if new_route:
            log.info(
                "vehicle sysid %d now speaks from %s (was %s, silent %.1f s)",
                sysid,
                _where(route),
                _where(vehicle.route),
                now - vehicle.last_seen,
            )
            vehicle.route = route
            vehicle.taken_over = True
        if max_k is not None and k is not None and k > max_k and instant:
            # beyond where its clock can be: refused (the assembler counts it); but a clock that really jumped
            # keeps stamping from there while no ordinary sample comes: after CLOCK_JUMP_S it is believed
            if vehicle.future_since is None:
                vehicle.future_since = now
            elif now - vehicle.future_since >= CLOCK_JUMP_S:
                return self._restart(vehicle, name, values, route, now, "clock jumped", k)
        vehicle.last_seen = now
        ready = asm.add(name, values, route, now, max_k, k, at[0] if at is not None else None)
        return [(vehicle, s) for s in ready] if ready else []

    @staticmethod
    def _max_k(vehicle: Vehicle, now: float) -> int | None:
        """The newest instant the vehicle's clock can have reached by ``now`` (None before its first sample)."""
        if vehicle.assembler.last_k is None or vehicle.last_sample_at is None:
            return None
        ahead = (now - vehicle.last_sample_at) * MAX_SPEEDUP / vehicle.model.plant.h
        return vehicle.assembler.last_k + FUTURE_SLACK + int(min(ahead, 1e9))

    def _restart(
        self, vehicle: Vehicle, name: str, values: tuple, route: object, now: float, why: str, k: int
    ) -> list[tuple[Vehicle, AssembledSample]]:
        log.info(
            "vehicle sysid %d restarted (%s %s, k %d -> %d): fresh estimator",
            vehicle.sysid,
            why,
            _where(route),
            vehicle.assembler.last_k,
            k,
        )
        self.counters.restarts += 1
        self._retire(vehicle.sysid)
        return self.message(vehicle.sysid, name, values, route, now)

    def poll(self, now: float) -> list[tuple[Vehicle, AssembledSample]]:
        """Samples whose bounded wait for an actuator report has run out."""
        out: list[tuple[Vehicle, AssembledSample]] = []
        for v in self.vehicles.values():
            if v.assembler.pending_instants():
                out.extend((v, s) for s in v.assembler.poll(now))
        return out

    def flush(self, now: float) -> list[tuple[Vehicle, AssembledSample]]:
        out: list[tuple[Vehicle, AssembledSample]] = []
        for v in self.vehicles.values():
            out.extend((v, s) for s in v.assembler.flush(now))
        return out

    def process(
        self, vehicle: Vehicle, sample: AssembledSample, wall: float, now: float | None = None
    ) -> Processed | None:
        """Step the vehicle's estimator on one assembled sample (control or observe-only).

        None when the values gate refuses the sample: a non-finite or out-of-envelope input never reaches
        the estimator (the estimator then predicts over the missing sample, as for a lost one).
        """
        model = vehicle.model
        sig = model.signals
        values = sample.values
        vehicle.last_sample_at = now if now is not None else vehicle.last_seen
        vehicle.future_since = None
        if sample.route == vehicle.route:
            vehicle.taken_over = False  # the new route's clock went on from the old one's: no restart to come
        reason = sig.reject_reason(values)
        if reason is not None:
            vehicle.rejected += 1
            self.counters.rejected_values += 1
            if vehicle.last_sample_at - vehicle.last_reject_log >= 10.0:
                vehicle.last_reject_log = vehicle.last_sample_at
                log.warning(
                    "vehicle sysid %d: sample k=%d rejected before the estimator (%s); %d so far",
                    vehicle.sysid,
                    sample.k,
                    reason,
                    vehicle.rejected,
                )
            return None
        inside: bool | None = None
        if model.envelope is not None:  # pick the point (before a non-finite schedule value is dropped below)
            point, inside = self._schedule(vehicle, model.envelope, values, sample.k)
            model = model.envelope.points[point]
            sig = model.signals
        if not all(map(math.isfinite, values.values())):
            for name in [n for n, v in values.items() if not math.isfinite(v)]:
                del values[name]  # a non-finite recorded-only signal is not recorded
        # the estimator works in deviations from the signal map's operating point (zero when it has none), or from
        # an envelope's trim interpolated at the sample
        trim = vehicle.trim
        y0, u0 = (trim[1], trim[2]) if trim is not None else (None, None)
        y, u_report = sig.deviations(values, y0, u0)
        est = model.estimator
        ki = est.plant.known_inputs  # [known_inputs]: the turn's terms from the sample's values (None: without)
        known = None
        if ki is not None:
            known = ki.vector(
                _lagged_inputs(vehicle, ki.lag, values, sample.k, model.plant.h) if ki.lag else values,
                vehicle.input_trim,
                vehicle.input_columns,
            )
        applied = None
        compensation: list[float] | None = None
        if self.observe:
            # u(k) issued by the vehicle is in this sample's report; u(k-1) stays from the previous one
            assert u_report is not None  # observe mode: a sample is complete only with its actuator report
            if self.compensate:
                c_prev = vehicle.last_compensation or [0.0] * len(u_report)
                c_in_force = _compensation_in_force(vehicle, values, c_prev)
                result, compensation = est.compensate(vehicle.state, sample.k, y, u_report, c_prev, known, c_in_force)
                vehicle.last_compensation = compensation
            else:
                result = est.observe(vehicle.state, sample.k, y, u_report, known=known)
            u_abs = [values[name] for name in sig.actuator]
        else:
            if u_report is None:
                vehicle.no_report += 1
                self.counters.no_report += 1
            elif est.plant.lags is None:  # past one sample the report is whichever command is in force
                applied = self._judge_applied(vehicle, sample.k, u_report)
            result = est.step(vehicle.state, sample.k, y, u_prev=u_report, applied=applied, known=known)
            vehicle.last_command = list(result.u_values)
            vehicle.last_command_k = sample.k
            u_abs = sig.absolute(vehicle.last_command, u0)
            lim = est.u_limit
            if lim is not None:  # u was saturated for u0 + u; this only takes off the last bit of rounding
                u_abs = [lim if v > lim else -lim if v < -lim else v for v in u_abs]
        if result.reset:
            self.counters.resets += 1
            log.error(
                "vehicle sysid %d: estimator state became non-finite at k=%d; reset to zero", vehicle.sysid, sample.k
            )
        vehicle.route = sample.route
        vehicle.processed += 1
        self.counters.processed += 1
        if result.skipped:
            vehicle.skipped += result.skipped
            self.counters.skipped += result.skipped
        t = sample.time_usec * 1e-6
        f_mag = max(map(abs, result.f_hat_values))
        event = vehicle.alarm.update(f_mag) if inside is not False else None  # outside: the alarm does not judge
        tau_obs = vehicle.delay.update(t, wall)
        processed = Processed(vehicle, sample, result, t, y, tau_obs, event, f_mag, applied, u_abs)
        processed.compensation = compensation
        if inside is not None:
            processed.point, processed.inside = vehicle.point, inside
        return processed

    def _schedule(self, vehicle: Vehicle, env: EnvelopeModel, values: dict[str, float], k: int) -> tuple[int, bool]:
        """The envelope's point for this sample and whether it is inside the identified range (module docstring);
        on a switch the vehicle's estimator state and last command are re-based into the new point's deviations."""
        sched = env.schedule
        x = [schedule_value(name, values) for name in sched.names]
        out = outside_variables(sched, x)
        previous = vehicle.point
        finite = all(map(math.isfinite, x))
        if finite:
            point = choose_point(sched, x, previous)
        else:  # no usable value: the point stays (the first sample's: the first point)
            point = previous if previous is not None else 0
        if finite or vehicle.trim is None:  # the trim, interpolated; without a value it stays where it was
            weights = trim_weights(sched, x) if finite else np.eye(len(sched.points))[point]
            trim = (
                weights @ env.offset_rows,
                tuple(float(v) for v in weights @ env.y0_rows),
                tuple(float(v) for v in weights @ env.u0_rows),
            )
            if vehicle.trim is not None:  # re-base the state (and the last command) into the new trim's deviations
                vehicle.state.z = rebase(vehicle.state.z, vehicle.trim[0], trim[0])
                if vehicle.last_command is not None:  # judged against the next report in the new deviations
                    old, new = vehicle.trim[2], trim[2]
                    vehicle.last_command = [c + a - b for c, a, b in zip(vehicle.last_command, old, new, strict=True)]
            vehicle.trim = trim
            vehicle.input_trim = {name: float(weights @ rows) for name, rows in env.input_trim_rows.items()}
            vehicle.input_columns = {name: weights @ rows for name, rows in env.input_column_rows.items()}
        if previous is not None and point != previous:
            vehicle.switches += 1
            log.info(
                "vehicle %d: envelope point %s -> %s at k=%d (%s)",
                vehicle.sysid,
                sched.points[previous],
                sched.points[point],
                k,
                _schedule_values(env, x, range(len(x))),
            )
        vehicle.point = point
        if out:
            vehicle.outside_samples += 1
            vehicle.outside_episode += 1
            self.counters.outside_envelope += 1
            if not vehicle.outside:
                vehicle.outside = True
                ranges = "; ".join(_envelope_range(env, i) for i in out)
                if hull_gap(sched, x) > 0 and all(
                    sched.low[i] - sched.below[i] <= x[i] <= sched.high[i] + sched.above[i] for i in out
                ):  # each value within its range, the combination not: say so
                    ranges += " (each within its range, but no point was identified near this combination)"
                log.warning(
                    "vehicle %d: %s outside the identified envelope %s: fault alarms paused",
                    vehicle.sysid,
                    _schedule_values(env, x, out),
                    ranges,
                )
        elif vehicle.outside:
            vehicle.outside = False
            log.info(
                "vehicle %d: %s back inside the identified envelope after %d sample(s) outside: fault alarms resume",
                vehicle.sysid,
                _schedule_values(env, x, range(len(x))),
                vehicle.outside_episode,
            )
            vehicle.outside_episode = 0
        return point, not out

    def _judge_applied(self, vehicle: Vehicle, k: int, reported: list[float]) -> bool | None:
        """Did the last command (for k-1, or earlier when samples were lost since) act? The report at k says so."""
        if vehicle.last_command is None or vehicle.last_command_k is None or vehicle.last_command_k >= k:
            return None  # samples lost since the last command do not matter: no command was sent for them
        applied = True
        for r, c in zip(reported, vehicle.last_command, strict=True):
            if abs(r - c) > APPLIED_TOLERANCE * max(1.0, abs(c)):
                applied = False
                break
        vehicle.applied.append(applied)
        if not applied:
            vehicle.not_applied += 1
            self.counters.not_applied += 1
        misses = vehicle.applied.count(False)
        if vehicle.commands_effective and misses >= NOT_APPLIED_ENTER:
            vehicle.commands_effective = False
            log.warning(
                "vehicle sysid %d: its commands are not taking effect (%d of the last %d not applied: late, "
                "lost or rejected); the estimator steps with the deflection it reports",
                vehicle.sysid,
                misses,
                len(vehicle.applied),
            )
        elif not vehicle.commands_effective and misses == 0 and len(vehicle.applied) == APPLIED_WINDOW:
            vehicle.commands_effective = True
            log.info("vehicle sysid %d: its commands take effect again", vehicle.sysid)
        return applied

    def _retire(self, sysid: int) -> Vehicle:
        v = self.vehicles.pop(sysid)
        self._retired.append(v)
        return v

    def shed_by_vehicle(self) -> dict[int, int]:
        """Samples shed per system id, over all its runs (restarts and expiries included)."""
        out: dict[int, int] = {}
        for v in (*self._retired, *self.vehicles.values()):
            if v.shed:
                out[v.sysid] = out.get(v.sysid, 0) + v.shed
        return out

    def assembly_totals(self) -> dict[str, int]:
        totals = AssemblyCounters().as_dict()
        for v in (*self._retired, *self.vehicles.values()):
            for key, value in v.assembler.counters.as_dict().items():
                totals[key] += value
        return totals

    @staticmethod
    def _warn_held(v: Vehicle, now: float) -> None:
        """A vehicle that was giving samples and now loses them for want of a latest value: WARNING while it lasts
        (10 s apart). Drops that are over by the check (a first VFR_HUD after the first samples) are only counted."""
        count = v.assembler.counters.held_missing
        if count == v.held_missing_seen or not v.processed:
            return
        stale = v.assembler.missing_held()
        if not stale:
            v.held_missing_seen = count
            return
        if now - v.held_missing_log >= 10.0:
            v.held_missing_log = now
            log.warning(
                "vehicle sysid %d: %d sample(s) dropped: %s (no time field) not heard within its hold; %d so far",
                v.sysid,
                count - v.held_missing_seen,
                ", ".join(stale),
                count,
            )
            v.held_missing_seen = count

    def expire(self, now: float) -> list[int]:
        """Drop vehicles silent for ``timeout`` seconds; returns their system ids."""
        gone = [s for s, v in self.vehicles.items() if now - v.last_seen > self.timeout]
        for sysid in gone:
            v = self._retire(sysid)
            self.counters.vehicles_expired += 1
            log.info("vehicle sysid %d silent for %.1f s: dropped after %d samples", sysid, self.timeout, v.processed)
        return gone

    def warn_missing(self, now: float) -> list[int]:
        """One WARNING per vehicle heard for a while whose messages never made a sample: what is missing."""
        warned = []
        for v in self.vehicles.values():
            self._warn_held(v, now)
            if v.processed or v.warned_missing or now - v.first_seen < MISSING_WARNING_S:
                continue
            asm = v.assembler
            missing = [m for m in (*asm.signals.messages(self.observe), *asm.needed_messages) if m not in asm.seen]
            if not missing and asm.expect_actuator:
                missing = [m for m in asm.signals.actuator_messages() if m not in asm.seen]
            stale = asm.missing_held() if not missing else ()
            what = (
                f"missing {', '.join(missing)}"
                if missing
                else f"{', '.join(stale)} (no time field: a latest value) is older than its hold"
                if stale
                else "its messages never share a sampling instant (check the time fields)"
            )
            log.warning(
                "vehicle sysid %d: telemetry arrives (%s) but never becomes a sample: %s (signal map: %s)",
                v.sysid,
                ", ".join(sorted(asm.seen)) or "nothing the signal map uses",
                what,
                asm.signals.describe(),
            )
            v.warned_missing = True
            warned.append(v.sysid)
        return warned


def _alive(route: object) -> bool:
    """Whether a bound source can still speak: a closed TCP connection cannot (its vehicle reconnects at once)."""
    peer = route[1] if isinstance(route, tuple) and len(route) == 2 else None
    closed = getattr(peer, "is_closed", None)
    return not closed() if callable(closed) else True


def _unit(env: EnvelopeModel, name: str) -> str:
    unit = env.unit(name)
    return f" {unit}" if unit else ""


def _schedule_values(env: EnvelopeModel, x: list[float], which) -> str:
    """``airspeed 30.2 m/s`` (the schedule's values ``which``; one that is not finite says so)."""
    names = env.schedule.names
    return ", ".join(
        f"{names[i]} {x[i]:.1f}{_unit(env, names[i])}" if math.isfinite(x[i]) else f"{names[i]} not a number"
        for i in which
    )


def _envelope_range(env: EnvelopeModel, i: int) -> str:
    """``36.0-62.0 m/s``: the points' values of schedule variable ``i`` (with its name when there are two)."""
    low, high = env.schedule.inside_range(i)
    name = env.schedule.names[i]
    prefix = f"{name} " if len(env.schedule.names) > 1 else ""
    return f"{prefix}{low:.1f}-{high:.1f}{_unit(env, name)}"


def _where(route: object) -> str:
    if isinstance(route, tuple) and len(route) == 2:
        link, peer = route
        return f"{link} peer {peer}"
    return str(route)
