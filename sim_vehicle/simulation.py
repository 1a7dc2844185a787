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

Late and lost. A command whose application time would be ``>= (k+1) h`` is late: it is discarded and
the actuator holds its last value for the next interval too (the paper leaves ``tau >= h`` to future
work; holding is what a real servo with a stale-command rule does). A sample never answered by ``(k+1) h``
is lost. A command for a sample older than the last applied one, or a repeat of it, is stale and ignored.

On-board autopilot (``autopilot``, a gain K with u(k) = K y(k)): the vehicle flies itself, as in an
observe-only run. At sample k it issues u(k) from its own measurement, saturated at the actuator limit,
reports it in that sample's ACTUATOR_OUTPUT_STATUS (the contract's observe-only meaning) and applies it at
``k h + tau(k)`` (the emulated on-board delay). Commands from outside are counted and ignored.
"""

from __future__ import annotations

import heapq
import itertools
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable, Iterator, Protocol

import numpy as np

from monitor.plant import Plant
from monitor.wire.mavlink import Sample
from monitor.wire.specs import DelaySampler, FaultSchedule, parse_delay_spec
from sim_vehicle.dynamics import Airframe
from sim_vehicle.network import DOWNLINK, UPLINK, Impairment
from sim_vehicle.stats import RunStats
from sim_vehicle.wind import Wind

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

    def payload(self, sysid: int, u: float, unit: str) -> dict:
        """The contract's truth payload plus extras (``status``, ``tau_drawn``, ``u``, ``elevator``, ...)."""
        status = "applied" if self.tau is not None else ("late" if self.late else "lost")
        return {
            "sysid": sysid, "k": self.k, "t": self.t, "x": self.x, "f": self.f, "d": self.d, "tau": self.tau,
            "status": status, "tau_drawn": self.tau_drawn, "u": [u], "elevator": self.elevator,
            "effectiveness": self.effectiveness, "stuck": self.stuck, "unit": unit,
        }


@dataclass
class Simulation:
    """One vehicle. Drive it with ``run_until(t)`` and ``receive_command(k, u, t_arrival)``."""

    plant: Plant
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

    def __post_init__(self) -> None:
        if self.plant.continuous is None:
            raise ValueError("the simulator needs a continuous plant (form = \"continuous\")")
        self.h = self.plant.h
        self.airframe = Airframe(self.plant.continuous, self.plant.actuator, x=self.x0)
        self._queue: list[tuple[float, int, Callable, tuple]] = []
        self._seq = itertools.count()
        self._wind: Iterator[float] = self.wind.values()
        self._pending: dict[int, SampleTruth] = {}
        self._arrivals: Counter = Counter()
        self.k = -1  # last sample taken
        self.last_applied = -1
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
        if self.autopilot is not None:
            return self._count("ignored_autopilot")
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
        if t_apply >= (k + 1) * self.h:
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
        self.airframe.advance_to(t)
        self._settle(k - 1)
        self.k = k
        f = self.fault.f_vector(k, self.plant.q)
        d = [next(self._wind)] + [0.0] * (self.plant.p - 1)
        stuck = self.fault.stuck(k)
        self.airframe.set_interval(np.array(f), np.array(d), self.fault.effectiveness(k), stuck is not None,
                                   None if stuck is None else stuck.value)
        tau = self.delay.tau(k)
        x = self.airframe.x.tolist()
        truth = SampleTruth(k=k, t=t, x=x, f=f, d=d, elevator=self.airframe.position,
                            effectiveness=self.airframe.effectiveness, stuck=self.airframe.stuck, tau_drawn=tau)
        self._pending[k] = truth
        self.stats.samples["taken"] += 1
        self.stats.tau_drawn.append(tau)
        measured = self._measure(k, x)
        reported = self.airframe.position
        if self.autopilot is not None:
            reported = self._autopilot(t, k, tau, measured)
        sample = Sample(sysid=self.sysid, k=k, t=t, alpha_deg=measured[0], q_deg_s=measured[1],
                        elevator_deg=reported)
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

    def _autopilot(self, t: float, k: int, tau: float, measured: list[float]) -> float:
        """Issue the on-board command for sample k; it acts after the drawn delay. Returns u(k)."""
        u = float((self.autopilot @ (self.plant.C @ np.asarray(measured))).ravel()[0])
        limit = self.plant.actuator.limit
        if limit is not None:
            u = min(max(u, -limit), limit)
        self._push(t + tau, self._apply, k, u)
        return u

    def _measure(self, k: int, x: list[float]) -> list[float]:
        if self.sensor_noise <= 0:
            return x
        rng = np.random.default_rng([self.seed, 0x5E5, k])
        return (np.asarray(x) + rng.normal(0.0, self.sensor_noise, size=len(x))).tolist()

    def _send(self, t: float, sample: Sample) -> None:
        self.stats.samples["sent"] += 1
        self.sink.send_sample(sample)

    def _apply(self, t: float, k: int, u: float) -> None:
        if k <= self.last_applied:
            self._count("stale")
            return
        self.airframe.advance_to(t)
        self.airframe.command(u)
        self.last_applied = k
        self._count("applied")
        tau = t - k * self.h
        self.stats.tau.append(tau)
        if k in self._pending:
            self._pending[k].tau = tau

    def _settle(self, k: int) -> None:
        truth = self._pending.pop(k, None)
        self._arrivals.pop(k - 2, None)
        if truth is None:
            return
        payload = truth.payload(self.sysid, self.airframe.target, self.plant.unit)
        self.stats.samples[payload["status"]] += 1
        self.sink.publish_truth(payload)

    def _heartbeat(self, t: float) -> None:
        self.sink.send_heartbeat()
        self._push(t + HEARTBEAT_PERIOD, self._heartbeat)

    def _finish(self, t: float, k: int) -> None:
        self.airframe.advance_to(t)
        self._settle(k - 1)
        self.done = True
