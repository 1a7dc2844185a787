"""The one interface between the vehicle's event logic and whatever flies: a ``FlightModel``.

Two implementations:

* ``LinearFlightModel`` (``sim_vehicle/dynamics.py``): the continuous plant of a plant file, integrated
  exactly (matrix exponentials) between events. Its state is the deviation from trim, so its trim
  deflection is 0.
* ``JSBSimFlightModel`` (``sim_vehicle/jsbsim_model.py``): a JSBSim aircraft, nonlinear 6-DOF, trimmed by
  JSBSim and integrated at JSBSim's own fixed step. Its elevator is an absolute deflection (trim included).

What stays outside the model, in ``Simulation`` / ``Airframe`` / the daemon: the servo (clipping to the
surface's travel, rate limit, stuck, loss of effectiveness), the fault and delay schedules, the wind of the
linear plant, the MAVLink link. A model only answers "fly ``T`` seconds with this deflection on the surface,
these additive faults and this wind", and "what are your outputs and true states now".

Units: degrees for angles and deflections, deg/s for rates, m/s for airspeed, seconds for time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

__all__ = ["FlightModel", "PilotedModel", "Outputs", "FlightModelError"]


class FlightModelError(RuntimeError):
    """The model cannot go on (an aircraft that crashed, left its envelope or produced NaN)."""


@dataclass(frozen=True)
class Outputs:
    """What the vehicle's sensors read at an instant (noise-free; the simulation adds sensor noise).

    ``theta_deg``/``airspeed_m_s`` are None for a model without them (the linear short-period plant);
    ``attitude`` carries the rest of a full attitude solution when the model has one:
    ``(roll_rad, yaw_rad, rollspeed_rad_s, yawspeed_rad_s)``, and ``hud`` VFR_HUD's other fields:
    ``(groundspeed_m_s, heading_deg, throttle_percent, alt_m, climb_m_s)``. ``elevator_parts``, for an aircraft
    flown by its own autopilot: ``(autopilot_deg, compensation_deg)``, the two parts of its elevator command.
    """

    alpha_deg: float
    q_deg_s: float
    theta_deg: float | None = None
    airspeed_m_s: float | None = None
    attitude: tuple[float, float, float, float] | None = None
    hud: tuple[float, float, int, float, float] | None = None
    elevator_parts: tuple[float, float] | None = None


@runtime_checkable
class FlightModel(Protocol):
    """A vehicle's flight physics, advanced by ``step`` from event to event (times never go backwards)."""

    name: str
    h: float  # sampling period (s)
    unit: str  # unit of the deflection, the faults and the angles ("deg")
    n_faults: int  # length of the additive fault vector f that ``step`` takes
    n_wind: int  # length of the external wind vector d that ``step`` takes (0: own weather)
    trim_deflection: float  # the deflection that holds the operating point (0 for a deviation model)
    travel: tuple[float | None, float | None]  # the surface's mechanical travel, (low, high); None: unlimited
    rate_limit: float | None  # servo slew rate (unit/s); None: the surface jumps
    state_names: tuple[str, ...]  # names of ``state()``'s entries, e.g. ("alpha_deg", "q_deg_s")
    t: float  # simulated time reached (s)

    def step(
        self, T: float, deflection: float, rate: float, f: Sequence[float] | np.ndarray, d: Sequence[float] | np.ndarray
    ) -> None:
        """Fly ``T`` seconds with the surface at ``deflection + rate * s`` (s from 0 to T), the additive fault
        ``f`` and the wind ``d`` held. ``deflection`` already includes the loss of effectiveness; how ``f``
        enters is the model's (the linear plant: through ``D_cf``; an aircraft: at the surface)."""
        ...

    def state(self) -> list[float]:
        """The true state now, in ``state_names`` order (the truth stream's ``x``)."""
        ...

    def outputs(self) -> Outputs:
        """The noise-free measurements now."""
        ...

    def disturbance(self) -> list[float]:
        """The model's own weather now (the truth stream's ``d`` when ``n_wind == 0``); [] otherwise."""
        ...

    def truth_extras(self) -> dict:
        """Keys the truth payload gets on top of the contract's (e.g. the deflection acting on the surface)."""
        ...

    def close(self) -> None:
        """Release what the model holds (an FDM instance); idempotent."""
        ...


@runtime_checkable
class PilotedModel(FlightModel, Protocol):
    """A ``FlightModel`` flown by its own autopilot (a JSBSim aircraft on a mission), driven by ``MissionServo``.

    Its elevator moves at every integration step (the autopilot's command plus the compensation received from
    outside), so the servo is the model's: ``fly`` replaces ``step``.
    """

    piloted: bool  # True: fly() it, not step()
    servo: float  # the servo's position now (deg): autopilot + compensation, clipped to the travel, or stuck
    servo_command: float  # the same before a stuck surface held it
    compensation: float  # the compensation in force (deg)

    def fly(
        self,
        T: float,
        compensation: float,
        effectiveness: float,
        stuck_at: float | None,
        f: Sequence[float] | np.ndarray,
    ) -> None:
        """Fly ``T`` seconds on the autopilot with this compensation (deg) added to its elevator, the surface's
        loss of effectiveness, a stuck surface's value (None: not stuck) and the additive fault ``f``."""
        ...
