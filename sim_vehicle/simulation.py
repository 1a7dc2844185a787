"""The vehicle as a discrete-event simulation in simulated time: no sockets, no clocks.

Events, processed strictly in time order (so the exact integrator never goes backwards):

* ``sample(k)`` at ``t = k h`` (time-driven sensor, Assumption 1): integrate to ``k h``, settle sample
  ``k - 1``, measure ``x(k)`` and the surface, draw ``tau(k)`` from the delay SPEC, hold fault ``f(k)``
  and wind ``d(k)`` over ``[k h, (k+1) h)``, and queue the telemetry datagram for ``k h + tau_sc(k)``.
* ``send(k)``: hand the (possibly duplicated or reordered) datagram to the transport.
* ``apply(k, u)`` (event-driven actuator): integrate to the application time with the previous
  deflection, then switch to ``u``.
* ``heartbeat`` every second of simulated time, ``finish`` at ``N h``.

Delay model. ``tau(k)`` drawn from the SPEC is the *total* sensor -> actuator delay, as in the contract
and the paper's Assumption 2. The telemetry of sample ``k`` is held ``tau_sc = split * tau(k)`` before it
is sent; the answering command is applied at ``max(arrival, k h + tau(k))``. So the real path (UDP and the
monitor's own computing time, in simulated time, i.e. multiplied by the speedup) is absorbed in the
``tau_ca`` budget, and only when it overruns that budget is the true delay larger than the drawn one.
The true ``tau(k)`` (application time minus ``k h``) is what the truth stream reports.

Late and lost. A command acts when it is due, even in a later interval than its own sample's, unless a newer
command has already acted (it is then stale and ignored: the newest command wins, as the monitor's lagged
model assumes). Only a command whose application time would be past ``k h + max(h, ceiling)`` is late: it
is discarded and the actuator holds (what a real servo with a stale-command rule does). ``ceiling`` is the
delay SPEC's largest draw, so for a SPEC within one sample (the paper's ``uniform:0:0.46`` at h = 1 s) late
means "not applied by (k+1) h", as the paper assumes, and for a SPEC past one sample (``uniform:0.05:0.12`` at
h = 0.05 s) every drawn delay acts. A sample is settled (its truth published) once its command's deadline
has passed; one never answered by then is lost. Each truth payload says which command was in force at its
instant (``in_force``) and, for the sample's own command, when it acted (``tau``, which may exceed h).

A mission (a JSBSim aircraft whose model carries one: ``--mission``). The aircraft's own autopilot flies it,
elevator included, at every JSBSim step (``sim_vehicle/autopilot.py``); the servo is ``MissionServo``. A command
from outside is then, with ``compensation``, an additive compensation in degrees: applied after its delay like any
command (same late/stale rules), it is added to the autopilot's elevator from then on; without ``compensation``
it is counted (``ignored_autopilot``) and ignored, and every sample is flown on board. The sample's
ACTUATOR_OUTPUT_STATUS reports the whole deflection applied (``actuator[0]``), the autopilot's part
(``actuator[1]``) and the compensation in force (``actuator[2]``).

On-board commands. With ``autopilot`` (a gain K with u(k) = K y(k), linear plant only) the vehicle flies
itself, as in an observe-only run; with ``excite`` (``--excite prbs:AMP:SECONDS``) it flies an identification
manoeuvre, trim +- AMP, for SECONDS, then issues trim once and goes back to commands from outside. At sample
k the on-board command is issued, saturated at the surface's travel, reported in that sample's
ACTUATOR_OUTPUT_STATUS (the contract's observe-only meaning) and applied at ``k h + tau(k)`` (the emulated
on-board delay). Meanwhile commands from outside are counted (``ignored_autopilot``, ``ignored_excitation``)
and ignored.

What flies is a ``FlightModel`` (``sim_vehicle/flight_model.py``): the linear plant built from ``plant``
(the default), or any model handed in as ``model`` (a JSBSim aircraft). Its servo and the faults at the
surface are ``Airframe``'s; the wind ``d(k)`` comes from ``wind`` for a model that takes it (the linear
plant), and from the model itself otherwise (JSBSim's turbulence, reported in the truth's ``d``).
"""

from __future__ import annotations

import heapq
import itertools
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from monitor.model.plant import Plant
from monitor.wire.specs import DelaySampler, Excitation, FaultSchedule, Wind, parse_delay_spec
from monitor.wire.telemetry import AircraftSample, Sample
from sim_vehicle.dynamics import Airframe, LinearFlightModel, MissionServo
from sim_vehicle.flight_model import FlightModel, Outputs, PilotedModel
from sim_vehicle.network import DOWNLINK, UPLINK, Impairment
from sim_vehicle.stats import RunStats

__all__ = ["Sink", "Simulation", "SampleTruth"]

HEARTBEAT_PERIOD = 1.0  # seconds of simulated time


class Sink(Protocol):
    """Where the simulation's outputs go (the daemon's transport, or a test)."""

    def send_sample(self, sample: Sample) -> None: ...
    def send_heartbeat(self) -> None: ...
    def publish_truth(self, payload: dict) -> None: ...


@dataclass
class SampleTruth:
    """What the simulator knows about sample ``k`` until it is settled at ``(k+1) h``."""

    k: int
    t: float
    x: list[float]
    f: list[float]
    d: list[float]
    elevator: float
    effectiveness: float
    stuck: bool
    tau_drawn: float
    tau: float | None = None
    late: bool = False
    onboard: bool = False  # the vehicle's own command (autopilot, excitation) acted, not an answer from outside
    in_force: int = -1  # the sample whose command was in force at this instant (-1: none yet)
    u_end: float | None = None  # the deflection commanded at the end of the interval (set when it ends)
    extras: dict = field(default_factory=dict)  # the model's own keys (an aircraft: surface, trim, ...)

    def payload(self, sysid: int, unit: str) -> dict:
        """The contract's truth payload plus extras (``status``, ``tau_drawn``, ``u``, ``elevator``, ...)."""
        if self.tau is not None:
            status = "applied"
        else:  # a mission flown on board without compensation: nobody was to answer, so nothing was lost
            status = "late" if self.late else "onboard" if self.onboard else "lost"
        return {
            "sysid": sysid,
            "k": self.k,
            "t": self.t,
            "x": self.x,
            "f": self.f,
            "d": self.d,
            "tau": self.tau,
            "status": status,
            "tau_drawn": self.tau_drawn,
            "u": [self.u_end],
            "in_force": self.in_force,
            "elevator": self.elevator,
            "effectiveness": self.effectiveness,
            "stuck": self.stuck,
            "unit": unit,
            **self.extras,
        }


@dataclass
class Simulation:
    """One vehicle. Drive it with ``run_until(t)`` and ``receive_command(k, u, t_arrival)``."""

    plant: Plant | None
    sink: Sink
    sysid: int = 1
    steps: int | None = None
    fault: FaultSchedule = field(default_factory=FaultSchedule)
    delay: DelaySampler = field(default_factory=lambda: parse_delay_spec("uniform:0:0.46"))
    wind: Wind = field(default_factory=Wind)
    impairment: Impairment = field(default_factory=Impairment)
    delay_split: float = 0.5
    sensor_noise: float = 0.0
    seed: int = 0
    x0: list[float] | None = None
    autopilot: np.ndarray | None = None  # m x l gain of the on-board controller (None: flown by commands)
    stats: RunStats = field(default_factory=RunStats)
    model: FlightModel | None = None  # what flies (None: the linear plant of ``plant``)
    excite: Excitation | None = None  # an on-board identification manoeuvre at the start
    compensation: bool = False  # a mission: commands from outside add to the autopilot's elevator (else ignored)

    def __post_init__(self) -> None:
        if self.model is None:
            if self.plant is None:
                raise ValueError("a Simulation needs a plant or a flight model")
            self.model = LinearFlightModel.from_plant(self.plant, self.x0)
        if self.autopilot is not None and self.plant is None:
            raise ValueError("the on-board autopilot u = K y needs the linear plant's C")
        self.h = self.model.h
        self.unit = self.model.unit
        # an aircraft on a mission flies its own elevator: commands from outside are a compensation, or ignored
        self.piloted = isinstance(self.model, PilotedModel) and self.model.piloted
        if self.compensation and not self.piloted:
            raise ValueError("compensation adds to an on-board autopilot's elevator: it needs an aircraft on a mission")
        if self.piloted and (self.autopilot is not None or self.excite is not None):
            raise ValueError("an aircraft on a mission is flown by its own autopilot: no autopilot gain, no excite")
        self.airframe: Airframe | MissionServo = (
            MissionServo(self.model) if isinstance(self.model, PilotedModel) and self.piloted else Airframe(self.model)
        )
        self._queue: list[tuple[float, int, Callable, tuple]] = []
        self._seq = itertools.count()
        self._wind: Iterator[float] | None = self.wind.values() if self.model.n_wind else None
        self._excite: list[int] = self.excite.signs(self.h, self.seed) if self.excite is not None else []
        self._pending: dict[int, SampleTruth] = {}
        self._arrivals: Counter = Counter()
        self.k = -1  # last sample taken
        self.last_applied = -1
        self.deadline = max(self.h, self.delay.ceiling)  # a command not applied by k h + deadline is late
        self.done = False
        self._push(0.0, self._sample, 0)
        self._push(0.0, self._heartbeat)

    # -- driving ---------------------------------------------------------------------------------
    def next_time(self) -> float | None:
        return self._queue[0][0] if self._queue else None

    def run_until(self, t_now: float) -> None:
        """Process every event due at or before ``t_now``, in time order."""
        while self._queue and self._queue[0][0] <= t_now and not self.done:
            t, _, fn, args = heapq.heappop(self._queue)
            fn(t, *args)

    def receive_command(self, k: int, u: float, t_arrival: float) -> str:
        """A command answering sample ``k`` reached the vehicle at ``t_arrival``; returns what became of it.

        ``t_arrival`` must not precede an event already processed (the daemon stamps arrivals with the
        current simulated time, which is never behind the event loop).
        """
        self.stats.commands["received"] += 1
        if self.autopilot is not None or (self.piloted and not self.compensation):
            return self._count("ignored_autopilot")
        if self._excite and k <= len(self._excite):
            return self._count("ignored_excitation")
        if k <= self.last_applied:
            return self._count("stale")
        if k > self.k or k < 0:
            return self._count("future")
        copy = self._arrivals[k]
        self._arrivals[k] += 1
        fate = self.impairment.fate(DOWNLINK, k, copy)
        if not fate:
            return self._count("dropped")
        extra, _ = fate[0]  # a downlink duplicate would be stale on arrival: only the first copy matters
        t_apply = max(t_arrival + extra, k * self.h + self.delay.tau(k))
        if t_apply >= k * self.h + self.deadline:
            if k in self._pending:
                self._pending[k].late = True
            return self._count("late")
        self._push(t_apply, self._apply, k, float(u))
        return "scheduled"

    # -- events ----------------------------------------------------------------------------------
    def _push(self, t: float, fn: Callable, *args) -> None:
        heapq.heappush(self._queue, (t, next(self._seq), fn, args))

    def _count(self, what: str) -> str:
        self.stats.commands[what] += 1
        return what

    def _sample(self, t: float, k: int) -> None:
        model = self.model
        assert model is not None  # __post_init__ made one
        self._end_interval(t, k - 1)
        self._settle_due(t)
        self.k = k
        x = model.state()
        outputs = model.outputs()
        f = self.fault.f_vector(k, model.n_faults)
        if self._wind is not None:
            d = [next(self._wind)] + [0.0] * (model.n_wind - 1)
            held = d
        else:
            d, held = model.disturbance(), []
        stuck = self.fault.stuck(k)
        self.airframe.set_interval(
            np.array(f),
            np.array(held),
            self.fault.effectiveness(k),
            stuck is not None,
            None if stuck is None else stuck.value,
        )
        tau = self.delay.tau(k)
        truth = SampleTruth(
            k=k,
            t=t,
            x=x,
            f=f,
            d=d,
            elevator=self.airframe.position,
            effectiveness=self.airframe.effectiveness,
            stuck=self.airframe.stuck,
            tau_drawn=tau,
            extras=model.truth_extras(),
            in_force=self.last_applied,
        )
        self._pending[k] = truth
        self.stats.samples["taken"] += 1
        self.stats.tau_drawn.append(tau)
        measured = self._measure(k, x)
        reported = self.airframe.position
        onboard = None
        if self.autopilot is not None:
            assert self.plant is not None  # __post_init__: the autopilot comes with the linear plant
            onboard = float((self.autopilot @ (self.plant.C @ np.asarray(measured))).ravel()[0])
        elif k <= len(self._excite) and self.excite is not None:  # the manoeuvre, then trim once
            level = self._excite[k] * self.excite.amplitude if k < len(self._excite) else 0.0
            onboard = model.trim_deflection + level
        if onboard is not None:
            reported = self._onboard(t, k, tau, onboard)
            truth.onboard = True
        elif self.piloted and not self.compensation:
            truth.onboard = True  # its own autopilot flies it and nobody answers: no sample is "in time" or "lost"
        sample = self._telemetry(k, t, measured, outputs, reported)
        fate = self.impairment.fate(UPLINK, k)
        if not fate:
            self.stats.samples["dropped"] += 1
        for extra, tag in fate:
            if tag != "ok":
                self.stats.samples[tag] += 1
            self._push(t + self.delay_split * tau + extra, self._send, sample)
        if self.steps is None or k + 1 < self.steps:
            self._push((k + 1) * self.h, self._sample, k + 1)
        else:
            self._push((k + 1) * self.h, self._finish, k + 1)

    def _onboard(self, t: float, k: int, tau: float, u: float) -> float:
        """Issue the on-board command u(k), saturated at the travel; it acts after the drawn delay. Returns it."""
        low, high = self.airframe.low, self.airframe.high
        if low is not None:
            u = max(u, low)
        if high is not None:
            u = min(u, high)
        self._push(t + tau, self._apply, k, u, True)
        return u

    def _telemetry(self, k: int, t: float, measured: list[float], outputs: Outputs, reported: float) -> Sample:
        """The sample as sent: noise (if any) on alpha and q; an aircraft's full attitude and VFR_HUD."""
        alpha = measured[0]
        q = measured[1] if len(measured) > 1 else 0.0
        if outputs.theta_deg is None:
            return Sample(sysid=self.sysid, k=k, t=t, alpha_deg=alpha, q_deg_s=q, elevator_deg=reported)
        return AircraftSample(
            sysid=self.sysid,
            k=k,
            t=t,
            alpha_deg=alpha,
            q_deg_s=q,
            elevator_deg=reported,
            theta_deg=outputs.theta_deg,
            airspeed_m_s=outputs.airspeed_m_s or 0.0,
            attitude=outputs.attitude or (0.0, 0.0, 0.0, 0.0),
            hud=outputs.hud or (0.0, 0.0, 0, 0.0, 0.0),
            autopilot_elevator=outputs.elevator_parts[0] if outputs.elevator_parts else 0.0,
            compensation=outputs.elevator_parts[1] if outputs.elevator_parts else 0.0,
        )

    def _measure(self, k: int, x: list[float]) -> list[float]:
        """The state as measured: seeded white noise on the linear plant's states, on an aircraft's alpha and q."""
        if self.sensor_noise <= 0:
            return x
        rng = np.random.default_rng([self.seed, 0x5E5, k])
        noisy = len(x) if isinstance(self.model, LinearFlightModel) else 2  # an aircraft's alpha and q only
        return (np.asarray(x[:noisy]) + rng.normal(0.0, self.sensor_noise, size=noisy)).tolist() + x[noisy:]

    def _send(self, t: float, sample: Sample) -> None:
        self.stats.samples["sent"] += 1
        self.sink.send_sample(sample)

    def _apply(self, t: float, k: int, u: float, onboard: bool = False) -> None:
        """Command ``u`` for sample ``k`` acts at ``t``; ``onboard``: the vehicle's own, not a received command."""
        if k <= self.last_applied:
            self._count("stale")
            return
        self.airframe.advance_to(t)
        self.airframe.command(u)
        self.last_applied = k
        if not onboard:  # the command counters are about what was received
            self._count("applied")
        tau = t - k * self.h
        self.stats.tau.append(tau)
        if k in self._pending:
            self._pending[k].tau = tau

    def _end_interval(self, t: float, k: int) -> None:
        """Integrate to the end of sample ``k``'s interval and note the deflection commanded then (its truth's u)."""
        self.airframe.advance_to(t)
        if k in self._pending:
            self._pending[k].u_end = self.airframe.target

    def _settle_due(self, t: float) -> None:
        """Settle every sample whose command can no longer act (its deadline has passed by ``t``), oldest first."""
        for k in sorted(self._pending):
            if k * self.h + self.deadline > t + 1e-12:
                break
            self._settle(k)

    def _settle(self, k: int) -> None:
        truth = self._pending.pop(k, None)
        self._arrivals.pop(k - 2, None)
        if truth is None:
            return
        payload = truth.payload(self.sysid, self.unit)
        # a sample flown on board was answered by nobody: counting it "in time" would credit a monitor
        self.stats.samples["onboard" if truth.onboard else payload["status"]] += 1
        self.sink.publish_truth(payload)

    def _heartbeat(self, t: float) -> None:
        self.sink.send_heartbeat()
        self._push(t + HEARTBEAT_PERIOD, self._heartbeat)

    def _finish(self, t: float, k: int) -> None:
        self._end_interval(t, k - 1)
        for pending in sorted(self._pending):  # the run ends: what has not acted by now never will
            self._settle(pending)
        self.done = True
