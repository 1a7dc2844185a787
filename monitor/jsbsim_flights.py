"""In-process JSBSim flights: the one module of the monitor that imports ``sim_vehicle`` (it needs jsbsim).

Why here and only here: ``fault-monitor detectability --monte-carlo N`` checks the prediction
(``monitor.checks.detectability``, linear algebra only) against the real thing, seeded flights of a JSBSim
aircraft in turbulence with the monitor's estimator closing the loop. That needs the vehicle's own event
simulation and flight model (``sim_vehicle.simulation.Simulation``, ``sim_vehicle.jsbsim_model``) in
process, without sockets or daemons. Everything else the monitor shares with the vehicle is the contract
(``monitor.wire``: specs, MAVLink, turbulence intensities), so the rest of the monitor never imports
``sim_vehicle``. Optional: nothing imports this module but the commands that fly (lazily), and the
``sim_vehicle`` modules are imported when a flight is flown (JSBSim itself when its aircraft is loaded).

``ClosedLoop`` is the monitor's ``Estimator`` answering the vehicle's samples at the instant they are sent: a
``Sink`` of ``sim_vehicle``'s event ``Simulation``, fed the vehicle's samples (a nonlinear JSBSim aircraft, or
the linear plant as sim-vehicle integrates it, with its link rule for delays past one sample) mapped by the
plant's signal map as the live service does. Why it is not ``monitor.model.simulate``: that one simulates the
linear discrete model itself; here the vehicle's simulation is the plant, and the estimator only answers it.

The Monte Carlo (:func:`monte_carlo`): the delay drawn uniformly over the plant's interval, seeded flights;
false alarms before onset, the predicted bias at onset, and per flight the smallest bias detected within T
(bisection on short flights).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from monitor.checks.calibration import calibrate_threshold, crossing_rates
from monitor.checks.detectability import Detectability, upcrossing_rate
from monitor.errors import UserError
from monitor.model.plant import Plant
from monitor.wire.telemetry import SAMPLE_FIELDS, Sample, quantities

if TYPE_CHECKING:
    from sim_vehicle.simulation import Simulation

__all__ = ["ClosedLoop", "sample_values", "MonteCarlo", "FlightPlan", "monte_carlo"]


def sample_values(signals) -> Callable:
    """A function sample -> ``{name: value}`` for the signals the estimator uses, as the link would decode them.

    Read from the sample's definition (``monitor.wire.telemetry``): each signal's field is looked up among the
    fields the vehicle's encoder fills, its wire value is the quantity over the field's scale, and the signal's
    own scale and offset apply as the link applies them. A map naming a field the vehicle does not send is a
    one-line error.
    """
    fields = {(f.message, f.field, f.index or 0): f for f in SAMPLE_FIELDS}
    readers = []
    for name in (*signals.outputs, *signals.actuator):
        sig = signals.measured[name]
        field = fields.get((sig.message, sig.field, sig.index))
        if field is None:
            raise UserError(
                f"the in-process flight cannot produce signal '{name}' ({sig.message}.{sig.field}"
                f"[{sig.index}]): it knows what sim-vehicle sends"
            )
        readers.append((name, field.name, sig.scale / field.scale, sig.offset))

    def read(sample: Sample) -> dict[str, float]:
        have = quantities(sample)
        return {name: scale * have.get(quantity, 0.0) + offset for name, quantity, scale, offset in readers}

    return read


class ClosedLoop:
    """The monitor's estimator answering the vehicle's samples at the instant they are sent (no network).

    A ``Sink`` for ``sim_vehicle.simulation.Simulation``: each sample is mapped by the signal map (deviations from
    its operating point), stepped, and the command goes back as the absolute deflection; with ``alarm`` (an
    ``AlarmConfig``) the alarm runs on ``|f_hat|`` and its raises are kept. ``fly(sim)`` runs the whole flight.

    Not ``monitor.model.simulate``'s loop, and kept apart from it: that one steps the linear discrete model
    itself, whereas here the plant is the vehicle's simulation (JSBSim's nonlinear aircraft, or sim-vehicle's
    exact integration of the continuous plant with its late-command rule) and the estimator only answers the
    samples it is sent, as the live service does.
    """

    def __init__(self, estimator, signals=None, alarm=None) -> None:
        from monitor.link.signals import default_signal_map
        from monitor.service.alarm import Alarm

        self.est = estimator
        self.state = estimator.initial_state()
        self.signals = signals if signals is not None else default_signal_map()
        self._values = sample_values(self.signals)
        self.alarm = Alarm(alarm) if alarm is not None else None
        self.events: list[tuple[int, str]] = []  # (sample, "raised" or "cleared")
        self.sim: Simulation | None = None
        self.now = 0.0
        self.f_hat: dict[int, float] = {}
        self.y: dict[int, list[float]] = {}  # outputs, deviations from the operating point
        self.u: dict[int, list[float]] = {}  # commands sent, likewise
        self.truth: dict[int, dict] = {}

    def send_sample(self, sample) -> None:
        y, u_report = self.signals.deviations(self._values(sample))
        step = self.est.step(self.state, sample.k, y, u_prev=u_report)
        self.f_hat[sample.k] = float(step.f_hat[0])
        self.y[sample.k], self.u[sample.k] = y, step.u.tolist()
        if self.alarm is not None:
            event = self.alarm.update(float(np.max(np.abs(step.f_hat))))
            if event is not None:
                self.events.append((sample.k, event))
        assert self.sim is not None  # samples come from the simulation fly() runs
        self.sim.receive_command(sample.k, self.signals.absolute(step.u)[0], self.now)

    def raised(self, first: int = 0, last: float = math.inf) -> list[int]:
        """Samples in ``[first, last)`` where the alarm raised."""
        return [k for k, e in self.events if e == "raised" and first <= k < last]

    def up_at(self, k: int) -> bool:
        """Whether the alarm was raised just before sample ``k``."""
        before = [e for j, e in self.events if j < k]
        return bool(before) and before[-1] == "raised"

    def send_heartbeat(self) -> None:
        pass

    def publish_truth(self, payload: dict) -> None:
        self.truth[payload["k"]] = payload

    def fly(self, sim) -> ClosedLoop:
        """Run ``sim`` to its end; an answer arrives when its sample is sent (the drawn delay is the whole delay)."""
        self.sim = sim
        while not sim.done:
            t = sim.next_time()
            self.now = t
            sim.run_until(t)
        return self


@dataclass
class MonteCarlo:
    """Flights against the prediction (plant units; rates per hour)."""

    flights: int
    aircraft: str
    turbulence: str
    hours: float  # of pre-fault flight, after the warm-up
    false_alarms: int  # raises at the threshold before onset
    false_alarms_per_hour: float
    predicted_per_hour: float  # 2 nu(c) at the threshold (an upper bound of raises)
    fhat_std: float  # observed, pooled over the pre-fault segments
    fhat_rho: float
    crossings: list[dict]  # per level: predicted and observed crossings of +-level per hour
    bias: float  # the bias flown at onset (the prediction's b_min)
    detected_within: int  # flights whose alarm raised within T of onset, at that bias
    detection_times_s: list[float | None]
    smallest_bias: list[float]  # per flight: the smallest bias detected within T (bisection)
    smallest_bias_95: float  # the empirical 95th percentile of it (what detects in 95 % of the flights)
    disturbance: dict | None  # sigma and time constant of d measured in the flights (equation error)
    seconds: float
    # the threshold calibrated from the flights' crossings (monitor.checks.calibration; None: too few to fit), and
    # the false alarms the flights had at it
    calibration: dict | None = None
    false_alarms_at_calibrated: int | None = None

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class FlightPlan:
    aircraft: str
    airspeed_kt: float = 100.0
    altitude_ft: float = 3000.0
    aircraft_dir: str | None = None
    minutes: float = 6.0  # pre-fault flight per seed (false alarms)
    warmup_s: float = 30.0  # before anything is counted, and before onset in the bisection flights
    bisections: int = 5
    seed: int = 0


def _fly(
    model, plan: FlightPlan, level: str, seed: int, seconds: float, bias: float, onset_k: int, alarm
) -> ClosedLoop:
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec
    from sim_vehicle.jsbsim_model import AircraftSpec, JSBSimFlightModel
    from sim_vehicle.simulation import Simulation

    plant = model.plant
    spec = AircraftSpec(
        plan.aircraft,
        aircraft_dir=plan.aircraft_dir,
        airspeed_kt=plan.airspeed_kt,
        altitude_ft=plan.altitude_ft,
        h=plant.h,
        turbulence=level,
        seed=seed,
    )
    loop = ClosedLoop(model.estimator, model.signals, alarm)
    fault = parse_fault_spec(f"bias:{bias!r}@{onset_k}" if bias else None)
    delay = parse_delay_spec(f"uniform:{plant.tau_min!r}:{plant.tau_max!r}", seed=seed)
    sim = Simulation(
        plant=None,
        sink=loop,
        steps=int(round(seconds / plant.h)),
        model=JSBSimFlightModel(spec),
        fault=fault,
        delay=delay,
        seed=seed,
    )
    return loop.fly(sim)


def _detected(loop: ClosedLoop, onset_k: int, window: int) -> int | None:
    """Samples from onset to the alarm's raise (0 when it was up at onset), None when not within ``window``."""
    if loop.up_at(onset_k):
        return 0
    raised = loop.raised(onset_k, onset_k + window + 1)
    return raised[0] - onset_k if raised else None


def monte_carlo(
    model, prediction: Detectability, flights: int, plan: FlightPlan, progress: Callable[[str], None] = lambda _: None
) -> MonteCarlo:
    """Fly ``flights`` seeded JSBSim flights at the prediction's turbulence and compare (module docstring)."""
    from monitor.service.alarm import AlarmConfig

    if prediction.turbulence is None:
        raise UserError("the Monte Carlo flies in turbulence: give --turbulence LEVEL")
    if flights < 1:
        raise UserError(f"--monte-carlo needs at least 1 flight, got {flights}")
    started = time.perf_counter()
    plant, h = model.plant, model.plant.h
    alarm = AlarmConfig(prediction.threshold, prediction.clear, prediction.alarm_samples)
    warm = int(round(plan.warmup_s / h))
    onset = warm + int(round(plan.minutes * 60.0 / h))
    window = int(math.floor(prediction.within_s / h + 1e-9))
    levels = [prediction.threshold * f for f in (0.5, 0.75, 1.0)]
    fh_all: list[np.ndarray] = []
    detections: list[float | None] = []
    smallest: list[float] = []
    disturbances: list[dict] = []
    false_alarms = 0
    for i in range(flights):
        seed = plan.seed + i
        loop = _fly(model, plan, prediction.turbulence, seed, (onset + window + 2) * h, prediction.bias, onset, alarm)
        fh = np.array([loop.f_hat[k] for k in range(warm, onset)])
        fh_all.append(fh)
        false_alarms += len(loop.raised(warm, onset))
        found = _detected(loop, onset, window)
        detections.append(None if found is None else found * h)
        if plant.lags is None and np.array_equal(plant.C, np.eye(plant.n)):  # the outputs are the state
            gust = _flight_disturbance(plant, model.signals, loop, warm, onset)
            if gust is not None:
                disturbances.append(gust)
        smallest.append(_smallest_bias(model, plan, prediction, seed, alarm, window))
        progress(
            f"flight {i + 1}/{flights} (seed {seed}): {len(loop.raised(warm, onset))} false "
            f"alarm(s) in {plan.minutes:g} min, std f_hat {fh.std():.3g}, bias {prediction.bias:.3g} "
            + ("not detected" if found is None else f"detected after {found * h:.2f} s")
            + f" within {prediction.within_s:g} s; smallest detected {smallest[-1]:.3g}"
        )
    hours = flights * (onset - warm) * h / 3600.0
    crossings = crossing_rates(fh_all, np.array(levels), h)[0]
    calibration = calibrate_threshold(fh_all, h, prediction.false_alarms_per_hour, prediction.threshold)
    at_calibrated = None
    if calibration is not None:  # the alarm's own logic over the same pre-fault estimates, at the calibrated level
        at_calibrated = sum(
            _raises(
                f,
                AlarmConfig(
                    calibration.threshold,
                    prediction.clear * calibration.threshold / prediction.threshold,
                    prediction.alarm_samples,
                ),
            )
            for f in fh_all
        )
    v0 = float(np.mean(np.concatenate(fh_all) ** 2))
    v1 = float(np.mean(np.concatenate([f[:-1] * f[1:] for f in fh_all])))
    std, rho = prediction.fhat_std, prediction.fhat_rho
    assert std is not None and rho is not None  # a turbulence prediction (checked above) carries them
    measured = None
    if disturbances:  # per flight; pooled as the rms sigma and the mean time constant
        measured = {
            "sigma": float(np.sqrt(np.mean([g["sigma"] ** 2 for g in disturbances]))),
            "time_constant": float(np.mean([g["time_constant"] for g in disturbances])),
            "how": "as fault-monitor identify measures it (the model's one-step residual on Dd), pre-fault",
        }
    return MonteCarlo(
        flights=flights,
        aircraft=plan.aircraft,
        turbulence=prediction.turbulence,
        hours=hours,
        false_alarms=false_alarms,
        false_alarms_per_hour=false_alarms / hours,
        predicted_per_hour=2 * 3600 * upcrossing_rate(prediction.threshold, std, rho, h),
        fhat_std=math.sqrt(v0),
        fhat_rho=v1 / v0 if v0 > 0 else 0.0,
        crossings=[
            {
                "level": c,
                "predicted_per_hour": 2 * 3600 * upcrossing_rate(c, std, rho, h),
                "observed_per_hour": float(n) / hours,
            }
            for c, n in zip(levels, crossings, strict=True)
        ],
        bias=prediction.bias,
        detected_within=sum(t is not None for t in detections),
        detection_times_s=detections,
        smallest_bias=smallest,
        smallest_bias_95=float(np.quantile(smallest, 0.95, method="higher")),
        disturbance=measured,
        seconds=time.perf_counter() - started,
        calibration=calibration.as_dict() if calibration is not None else None,
        false_alarms_at_calibrated=at_calibrated,
    )


def _raises(f_hat: np.ndarray, config) -> int:
    """How many times the alarm (``monitor.service.alarm``) raises over one series of |f_hat|."""
    from monitor.service.alarm import Alarm

    alarm = Alarm(config)
    return sum(alarm.update(abs(float(v))) == "raised" for v in f_hat)


def _flight_disturbance(plant: Plant, signals, loop: ClosedLoop, first: int, last: int) -> dict | None:
    """The gust over samples [first, last) of one flight, measured as ``fault-monitor identify`` does, from what the
    monitor measured and sent (a plant within one sample: every command acts in its own interval)."""
    from monitor.model.identification import gust_from_residual

    ks = np.arange(first, last)
    x = np.array([loop.y[k] for k in range(first, last)])
    u = np.array([loop.u[k] for k in range(first, last)])
    return gust_from_residual(ks, x, u, plant.A, plant.B0 + plant.B1, tuple(signals.outputs), plant.h)


def _smallest_bias(model, plan: FlightPlan, prediction: Detectability, seed: int, alarm, window: int) -> float:
    """The smallest bias this seed's air lets the alarm detect within T: bisection over short flights."""
    h = model.plant.h
    onset = int(round(plan.warmup_s / h))
    seconds = (onset + window + 2) * h
    level = prediction.turbulence
    assert level is not None  # monte_carlo flies a turbulence prediction

    def detected(b: float) -> bool:
        loop = _fly(model, plan, level, seed, seconds, b, onset, alarm)
        return _detected(loop, onset, window) is not None

    lo, hi = 0.0, prediction.bias
    while not detected(hi):
        lo, hi = hi, 2.0 * hi
        if hi > 64 * prediction.bias:
            return math.inf
    for _ in range(plan.bisections):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if detected(mid) else (mid, hi)
    return hi
