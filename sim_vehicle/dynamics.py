"""The linear flight model (exact between events) and the elevator servo that drives any flight model.

``LinearFlightModel``: the continuous plant of a plant file. Why exact: the monitor is judged against this
simulator, so integration error must not masquerade as a fault. Between two events (a sampling instant, a
command reaching the actuator, the surface reaching a rate-limited target) every input is affine in time,
and

    x(t0 + T) = e^{A_c T} x0 + Gamma1(T) (B_c u0 + w) + Gamma2(T) B_c r,
    Gamma1(T) = int_0^T e^{A_c s} ds,   Gamma2(T) = int_0^T e^{A_c s} (T - s) ds,

for ``u(t0 + s) = u0 + r s`` and the constant ``w = D_cf f(k) + D_cd d(k)``. All three matrices come from
one exponential of a Van Loan block matrix (the same idea as ``monitor.model.discretize.integral_expm``, one
block larger for the ramp), so there are no Euler steps and no quadrature tolerance.

``MissionServo``: the same interface for an aircraft flown by its own autopilot (a mission), whose servo moves at
every JSBSim step and so lives in the flight model; it keeps the compensation received and the faults.

``Airframe``: the elevator servo and the deflection faults, in front of any ``FlightModel`` (the linear plant
or a JSBSim aircraft). The commanded deflection is clipped to the surface's travel; with a rate limit the
surface slews towards it (a ramp segment), otherwise it jumps. A ``stuck`` fault freezes the surface;
``loe`` scales its effect (``u_eff = effectiveness * position``) while its measured position is unchanged,
as for a damaged surface whose position sensor still reads the servo. The additive fault ``f`` and the
wind ``d`` are held over each sampling interval and handed to the model with the deflection.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.linalg import expm

from monitor.model.plant import Actuator, ContinuousModel, Plant
from sim_vehicle.flight_model import FlightModel, Outputs, PilotedModel

__all__ = ["segment_matrices", "LinearFlightModel", "Airframe", "MissionServo"]


def segment_matrices(A_c: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(e^{A_c T}, Gamma1(T), Gamma2(T))`` from one exponential of ``[[A, I, 0], [0, 0, I], [0, 0, 0]] T``."""
    n = A_c.shape[0]
    block = np.zeros((3 * n, 3 * n))
    block[:n, :n] = A_c
    block[:n, n : 2 * n] = np.eye(n)
    block[n : 2 * n, 2 * n :] = np.eye(n)
    E = expm(block * T)
    return E[:n, :n], E[:n, n : 2 * n], E[:n, 2 * n :]


class LinearFlightModel:
    """``x' = A_c x + B_c u + D_cf f + D_cd d`` integrated exactly; ``x`` is the deviation from trim.

    A ``FlightModel``: the fault ``f`` enters through ``D_cf`` and the wind ``d`` through ``D_cd`` (the paper's
    model), the deflection through ``B_c``.
    """

    def __init__(
        self,
        model: ContinuousModel,
        h: float = 1.0,
        actuator: Actuator | None = None,
        x: Sequence[float] | None = None,
        name: str = "linear",
        unit: str = "deg",
    ) -> None:
        self.model = model
        self.h = float(h)
        self.name = name
        self.unit = unit
        n = model.A_c.shape[0]
        self.x = np.zeros(n) if x is None else np.asarray(x, dtype=float).copy()
        if self.x.shape != (n,):
            raise ValueError(f"the initial state needs {n} values, got {self.x.size}")
        actuator = actuator or Actuator()
        limit = actuator.limit
        self.travel: tuple[float | None, float | None] = (-limit, limit) if limit is not None else (None, None)
        self.rate_limit = actuator.rate_limit
        self.trim_deflection = 0.0
        self.n_faults = model.D_cf.shape[1]
        self.n_wind = model.D_cd.shape[1]
        self.state_names: tuple[str, ...] = ("alpha_deg", "q_deg_s") if n == 2 else tuple(f"x{i + 1}" for i in range(n))
        self.t = 0.0
        self._cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    @classmethod
    def from_plant(cls, plant: Plant, x0: Sequence[float] | None = None) -> LinearFlightModel:
        if plant.continuous is None:
            raise ValueError('the simulator needs a continuous plant (form = "continuous")')
        return cls(plant.continuous, plant.h, plant.actuator, x0, plant.name, plant.unit)

    def step(
        self, T: float, deflection: float, rate: float, f: Sequence[float] | np.ndarray, d: Sequence[float] | np.ndarray
    ) -> None:
        phi, g1, g2 = self._matrices(T)
        B = self.model.B_c[:, 0]
        w = self.model.D_cf @ np.asarray(f, dtype=float) + self.model.D_cd @ np.asarray(d, dtype=float)
        self.x = phi @ self.x + g1 @ (B * deflection + w) + g2 @ (B * rate)
        self.t += T

    def state(self) -> list[float]:
        return self.x.tolist()

    def outputs(self) -> Outputs:
        x = self.x
        return Outputs(alpha_deg=float(x[0]), q_deg_s=float(x[1]) if x.size > 1 else 0.0)

    def disturbance(self) -> list[float]:
        return []

    def truth_extras(self) -> dict:
        return {}

    def close(self) -> None:
        pass

    def _matrices(self, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        key = round(T, 12)
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) > 64:
                self._cache.clear()
            hit = self._cache[key] = segment_matrices(self.model.A_c, T)
        return hit


def _clip(u: float, low: float | None, high: float | None) -> float:
    if low is not None and u < low:
        return float(low)
    if high is not None and u > high:
        return float(high)
    return float(u)


class Airframe:
    """A flight model and its elevator servo, advanced from event to event.

    Call ``set_interval`` at each sampling instant (fault and wind are held over the interval),
    ``command`` when a command reaches the actuator, and ``advance_to`` before either, with
    non-decreasing times. ``Airframe(ContinuousModel, Actuator, x=...)`` builds the linear model.
    """

    def __init__(
        self, model: FlightModel | ContinuousModel, actuator: Actuator | None = None, x: Sequence[float] | None = None
    ) -> None:
        flight: FlightModel
        if isinstance(model, ContinuousModel):
            flight = LinearFlightModel(model, actuator=actuator, x=x)
        elif actuator is not None or x is not None:
            raise ValueError("actuator and x belong to the linear model; a FlightModel brings its own")
        else:
            flight = model
        self.flight = flight
        self.low, self.high = flight.travel
        self.rate_limit = flight.rate_limit
        self.t = flight.t
        self.position = float(flight.trim_deflection)  # measured surface deflection, plant units
        self.target = self.position  # commanded deflection after clipping (trim until the first command)
        self.effectiveness = 1.0
        self.stuck = False
        self.f = np.zeros(flight.n_faults)
        self.d = np.zeros(flight.n_wind)

    @property
    def x(self) -> np.ndarray:
        return np.asarray(self.flight.state())

    def set_interval(
        self,
        f: Sequence[float] | np.ndarray,
        d: Sequence[float] | np.ndarray,
        effectiveness: float = 1.0,
        stuck: bool = False,
        stuck_value: float | None = None,
    ) -> None:
        """Hold fault ``f`` and wind ``d`` from now on; apply the deflection faults of this interval."""
        self.f = np.asarray(f, dtype=float)
        self.d = np.asarray(d, dtype=float)
        self.effectiveness = float(effectiveness)
        if stuck and not self.stuck and stuck_value is not None:
            self.position = float(stuck_value)
        released = self.stuck and not stuck
        self.stuck = stuck
        if released and self.rate_limit is None:
            self.position = self.target  # a freed servo goes to its current command (slews if rate-limited)

    def command(self, u: float) -> None:
        """A command reaches the actuator now: clip it to the travel and move (or start slewing) the surface."""
        self.target = _clip(u, self.low, self.high)
        if not self.stuck and self.rate_limit is None:
            self.position = self.target

    def advance_to(self, t: float) -> None:
        """Fly from ``self.t`` to ``t`` (splitting where a slewing surface reaches its target)."""
        if t < self.t - 1e-12:
            raise ValueError(f"time goes backwards: {t} < {self.t}")
        while t > self.t:
            T = t - self.t
            rate = 0.0
            gap = self.target - self.position
            # the rate limit while the surface slews (None: it is where it was told to be, or it jumps)
            slewing = self.rate_limit if not self.stuck and gap != 0.0 else None
            if slewing is not None:
                rate = float(np.sign(gap)) * slewing
                T = min(T, abs(gap) / slewing)
            self.flight.step(T, self.effectiveness * self.position, self.effectiveness * rate, self.f, self.d)
            if slewing is not None:
                done = T >= abs(gap) / slewing
                self.position = self.target if done else self.position + rate * T
            self.t = t if T >= t - self.t else self.t + T

    @property
    def u_effective(self) -> float:
        return self.effectiveness * self.position


class MissionServo:
    """The elevator servo of an aircraft flown by its own autopilot (``--mission``): ``Airframe``'s interface.

    Why not ``Airframe``: its servo moves only when a command acts, and holds the deflection between events; an
    autopilot moves the elevator at every JSBSim step. So the servo lives in the flight model's own step loop
    (``JSBSimFlightModel.fly``), and this class keeps what the event logic decides: the compensation received
    from outside (``command``, after its delay; 0 until the first one), the surface faults of the interval
    (``set_interval``: loss of effectiveness, stuck, the additive fault), and what the servo reported last
    (``position``, the absolute deflection it put out, i.e. autopilot + compensation clipped to the travel, or
    the stuck value; ``target``, the same before a stuck surface held it).
    """

    def __init__(self, flight: PilotedModel) -> None:
        self.flight = flight
        self.low, self.high = flight.travel
        self.rate_limit = None
        self.t = flight.t
        self.position = float(flight.trim_deflection)
        self.target = self.position
        self.compensation = 0.0
        self.effectiveness = 1.0
        self.stuck = False
        self._stuck_at: float | None = None
        self.f = np.zeros(flight.n_faults)

    def set_interval(
        self,
        f: Sequence[float] | np.ndarray,
        d: Sequence[float] | np.ndarray,
        effectiveness: float = 1.0,
        stuck: bool = False,
        stuck_value: float | None = None,
    ) -> None:
        """Hold the additive fault ``f`` and the deflection faults from now on (``d``: the aircraft's own weather)."""
        self.f = np.asarray(f, dtype=float)
        self.effectiveness = float(effectiveness)
        if stuck and not self.stuck:  # frozen where the servo is now, or at the fault's value
            self._stuck_at = self.position if stuck_value is None else float(stuck_value)
            self.position = self._stuck_at
        elif not stuck:
            self._stuck_at = None
        self.stuck = stuck

    def command(self, u: float) -> None:
        """A compensation (deg) reaches the servo now: it is added to the autopilot's elevator from now on."""
        self.compensation = float(u)
        self.flight.compensation = self.compensation

    def advance_to(self, t: float) -> None:
        """Fly from ``self.t`` to ``t`` on the autopilot, with the compensation and the faults in force."""
        if t < self.t - 1e-12:
            raise ValueError(f"time goes backwards: {t} < {self.t}")
        if t > self.t:
            self.flight.fly(t - self.t, self.compensation, self.effectiveness, self._stuck_at, self.f)
            self.t = t
        self.position = self.flight.servo
        self.target = self.flight.servo_command

    @property
    def u_effective(self) -> float:
        return self.effectiveness * self.position
